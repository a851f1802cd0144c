"""The live view's page as a person meets it, in headless Chromium at 1280×800 and 1920×1080, for a one-axis run (the
simulated side-force rig with its live view) and a six-axis run (the live_view node in this process, told the program
is six-axis, fed the six-axis estimator's topics, the one-axis estimator's 'not applicable' status and the crane's):

- no two texts the page draws overlap: the DOM's text (each text node's line boxes, clipped by the boxes that clip
  it) and the text drawn on its canvases (the boxes the drawing code computed, ``window.__textBoxes``), and no text
  is cut by its cell;
- a six-axis run leads with the 6×6: its status is the first status on the page, nothing of the one-axis fit is
  shown, every panel has its place before the first fit and keeps it when the fit comes (each says "waiting" until
  then);
- the screenshots of both pages are saved in out/live_view/ (docs/figures/ holds copies of the 1280×800 ones).
"""
from __future__ import annotations

import shutil
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState

from crane_stiffness.contract import stiffness6_layout
from crane_stiffness.contract.status import OK
from crane_stiffness.estimation.live_status import not_applicable_message
from crane_stiffness.full6.reference import k2_of, reference_at_rest
from crane_stiffness.launcher.rosrun import installed_config
from crane_stiffness.model import solve_equilibrium
from crane_stiffness.model.geometry import WIRE_NAMES
from crane_stiffness.model.rotation import matrix_to_quaternion
from helpers import REPO
from helpers.browser import Browser
from helpers.view_rig import ViewRig
from helpers.live_rig import live_rig, wait_for_pairs

pytestmark = pytest.mark.ros

SHOTS = REPO / 'out' / 'live_view'
SIZES = ((1280, 800), (1920, 1080))
#: Every text box of the page in page coordinates: {text, where, left, top, width, height}, and the texts cut by the
#: box that clips them (a number wider than its cell).
TEXT_BOXES_JS = r"""(() => {
  const clip = (el, r) => {
    for (let a = el; a && a !== document.body; a = a.parentElement) {
      const cs = getComputedStyle(a);
      if (cs.overflowX !== 'visible' || cs.overflowY !== 'visible') {
        const c = a.getBoundingClientRect();
        r = { l: Math.max(r.l, c.left), t: Math.max(r.t, c.top), r: Math.min(r.r, c.right),
          b: Math.min(r.b, c.bottom) };
      }
    }
    return r;
  };
  const boxes = [], cut = [];
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) {
    const el = n.parentElement;
    if (!n.textContent.trim() || el.closest('select, script, style, title')) continue;
    const range = document.createRange();
    range.selectNodeContents(n);
    for (const q of range.getClientRects()) {
      const r = clip(el, { l: q.left, t: q.top, r: q.right, b: q.bottom });
      if (r.r - r.l > 0.5 && r.b - r.t > 0.5) {
        boxes.push({ text: n.textContent.trim().slice(0, 60), where: el.id || el.tagName.toLowerCase(),
          left: r.l + scrollX, top: r.t + scrollY, width: r.r - r.l, height: r.b - r.t });
      }
    }
    if (el.offsetParent && getComputedStyle(el).overflowX === 'hidden' && el.scrollWidth > el.clientWidth + 1) {
      cut.push(`${el.id || el.tagName}: ${n.textContent.trim()}`);
    }
  }
  for (const s of document.querySelectorAll('select')) {
    if (!s.offsetParent) continue;
    const q = s.getBoundingClientRect();
    boxes.push({ text: s.value, where: 'select', left: q.left + scrollX, top: q.top + scrollY, width: q.width,
      height: q.height });
  }
  for (const id of ['xy', 'scene', 'k6int']) {
    const c = document.getElementById(id);
    if (!c.offsetParent) continue;
    const q = c.getBoundingClientRect();
    for (const b of window.__textBoxes[id]) {
      if (b.left < 0 || b.top < 0 || b.left + b.width > c.width || b.top + b.height > c.height) {
        cut.push(`${id}: ${b.text} outside the canvas`);
      }
      boxes.push({ text: b.text, where: id, left: q.left + c.clientLeft + scrollX + b.left,
        top: q.top + c.clientTop + scrollY + b.top, width: b.width, height: b.height });
    }
  }
  return { boxes, cut };
})()"""
#: The places of the panels: (selector, left, top, width, height) of each heading, table and canvas shown.
PLACES_JS = r"""[...document.querySelectorAll('main h2, main table, main canvas, main pre, main p')]
  .filter((e) => e.offsetParent).map((e, i) => { const r = e.getBoundingClientRect();
    return [e.id || `${e.tagName} ${i}`, r.left, r.top + scrollY, r.width, r.height]; })"""
#: The status badges shown (class level-N, the connection's left out), in reading order: [id, top, left].
BADGES_JS = r"""[...document.querySelectorAll('main [class^="level-"]')].filter((e) => e.offsetParent)
  .map((e) => { const r = e.getBoundingClientRect(); return [e.id, r.top + scrollY, r.left]; })
  .sort((a, b) => a[1] - b[1] || a[2] - b[2])"""
#: What the page must show before its boxes are read: every panel drawn from its data.
ONE_AXIS_READY = ("document.getElementById('k-loading')?.dataset.value && "
                  "document.getElementById('status-level').dataset.level && "
                  "Number(document.getElementById('xy').dataset.loadingPoints) >= 100 && "
                  "document.getElementById('scene').dataset.drawn === 'crane' && "
                  "document.querySelector('#wires td:nth-child(2)').dataset.value !== undefined")


def overlapping(boxes: list[dict[str, Any]], tolerance: float = 1.0) -> list[tuple[str, str]]:
    """The pairs of boxes whose intersection is wider and higher than ``tolerance`` (CSS px)."""
    out = []
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            w = min(a['left'] + a['width'], b['left'] + b['width']) - max(a['left'], b['left'])
            h = min(a['top'] + a['height'], b['top'] + b['height']) - max(a['top'], b['top'])
            if w > tolerance and h > tolerance:
                out.append((f"{a['where']}: {a['text']}", f"{b['where']}: {b['text']}"))
    return out


def check_texts(browser: Browser) -> int:
    """No two texts overlap, none is cut; returns how many were read."""
    found = browser.evaluate(TEXT_BOXES_JS)
    assert not found['cut'], found['cut']
    assert not overlapping(found['boxes']), overlapping(found['boxes'])
    return len(found['boxes'])


def test_one_axis_page_no_text_covers_another(install_tree, rclpy_context, tmp_path, chromium_path):
    install, env = install_tree
    with live_rig(env, installed_config(install), tmp_path, rclpy_context) as (procs, watcher, ports):
        wait_for_pairs(procs, watcher, 2000)
        for width, height in SIZES:
            browser = Browser(chromium_path, tmp_path / f'chromium_{width}.log', size=(width, height))
            try:
                browser.open(f'http://127.0.0.1:{ports["http_port"]}/')
                browser.wait_for(ONE_AXIS_READY)
                assert browser.evaluate('document.body.dataset.run') == 'one_axis'
                # the one-axis fit leads: its plot, estimate and status shown; no 6x6 panel
                assert browser.evaluate("document.getElementById('stiffness6-panel').offsetParent") is None
                assert browser.evaluate("document.getElementById('xy').offsetParent !== null")
                badges = browser.evaluate(BADGES_JS)
                assert [b[0] for b in badges] == ['status-level'], badges
                # the prediction is the estimator's own (its axis, its unit), shown in the unit of the fit
                axis = browser.evaluate("[state.data.status.axis, state.data.status.unit, "
                                        "document.getElementById('k-prediction').textContent]")
                assert axis[:2] == ['fy', 'N/m'] and axis[2].endswith(' N/m'), axis
                assert check_texts(browser) > 40
                png = browser.screenshot(tmp_path / f'one_axis_{width}.png', full_page=True)
            finally:
                browser.close()
        procs.check_alive(allow_exit=('load_program',))
    SHOTS.mkdir(parents=True, exist_ok=True)
    for width, _ in SIZES:
        shutil.copy(tmp_path / f'one_axis_{width}.png', SHOTS / f'page_one_axis_{width}.png')
    assert png.stat().st_size > 10_000


class _SixAxisRig(ViewRig):
    """The live_view node told of a six-axis program, and a node publishing what a six-axis run publishes, in one
    context spun on a thread of its own."""

    def __init__(self, ctx: Any) -> None:
        super().__init__(ctx, 'six_axis_page_publisher', six_axis_program=True)

    def publish_crane(self) -> None:
        """The crane under the first load of the six-axis program (config/program_full6.yaml, step 1): its pose, its
        wires' lengths and tensions as the model gives them, the load."""
        load = np.array([1.9904, -3.2485, -0.3763, -1.5980, -0.9513, -0.2398])
        eq = solve_equilibrium(self.view.geometry, load=load)
        stamp = self.pub.get_clock().now().to_msg()
        wires = JointState(name=list(WIRE_NAMES), position=[float(v) for v in eq.wire_lengths],
                           effort=[float(v) for v in eq.wire_tensions])
        wires.header.stamp = stamp
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp, 'crane_base'
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in eq.displacement)
        q = matrix_to_quaternion(eq.rotation)
        pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z, pose.pose.orientation.w = (
            float(v) for v in q)
        wrench = WrenchStamped()
        wrench.header.stamp, wrench.header.frame_id = stamp, 'crane_base'
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = (float(v) for v in load[:3])
        wrench.wrench.torque.x, wrench.wrench.torque.y, wrench.wrench.torque.z = (float(v) for v in load[3:])
        self.pose.publish(pose)
        self.wrench.publish(wrench)
        self.wires.publish(wires)

    def publish_not_applicable(self) -> None:
        """/stiffness/estimate as the one-axis estimator publishes it in a six-axis program."""
        message = not_applicable_message('fy')
        self.estimate.publish(DiagnosticArray(status=[
            DiagnosticStatus(name=f'/stiffness_estimator: {part}', level=bytes([OK]), message=message,
                             values=[KeyValue(key='axis', value='fy'), KeyValue(key='unit', value='N/m')])
            for part in ('loading', 'unloading', 'input')]))

    def publish_fit(self, k: np.ndarray) -> None:
        c = np.linalg.inv(k)
        self.k.publish(stiffness6_layout.to_message(k, k * 0.995, k * 1.005))
        self.c.publish(stiffness6_layout.to_message(c, c * 0.995, c * 1.005))
        status = DiagnosticStatus(name='stiffness6_estimator: 6x6', hardware_id='crane', level=bytes([OK]),
                                  message='OK: 26 steps, 21753 pairs, condition 2.67, lack of fit 0.777 (p = 0.96)')
        k2 = k2_of(k)
        status.values = [KeyValue(key='k2', value=f'{k2:.8g}'),
                         KeyValue(key='k2_ci95', value=f'{0.995 * k2!r} .. {1.005 * k2!r}')]
        self.status6.publish(DiagnosticArray(status=[status]))


def test_six_axis_page_leads_with_the_6x6_in_a_stable_layout_and_no_text_covers_another(rclpy_context, tmp_path,
                                                                                      chromium_path):
    with _SixAxisRig(rclpy_context) as rig:
        tangent = reference_at_rest(rig.view.geometry).tangent
        measured = tangent * (1.0 + np.random.default_rng(6).uniform(-0.006, 0.006, (6, 6)))
        assert rig.view.page is not None
        rig.publish_not_applicable()
        for n, (width, height) in enumerate(SIZES):
            browser = Browser(chromium_path, tmp_path / f'chromium_{width}.log', size=(width, height))
            try:
                browser.open(f'http://127.0.0.1:{rig.view.page.port}/')
                browser.wait_for("document.getElementById('connection')?.textContent === 'connected'")
                assert browser.evaluate('document.body.dataset.run') == 'six_axis'
                if n == 0:  # before the first fit: every panel in its place, saying it waits
                    rig.publish_crane()
                    browser.wait_for("document.getElementById('scene').dataset.drawn === 'crane'")
                    before = browser.evaluate(PLACES_JS)
                    waiting = browser.evaluate("[document.getElementById('stiffness6-level').textContent, "
                                               "document.getElementById('stiffness6-k2').textContent, "
                                               "document.querySelector('#stiffness6 td').textContent]")
                    assert waiting[0] == 'WAITING' and 'waiting' in waiting[1] and waiting[2] == '–', waiting
                    check_texts(browser)
                    rig.publish_fit(measured)
                    rig.publish_crane()
                browser.wait_for("document.getElementById('stiffness6-level').dataset.level === '0' && "
                                 "document.querySelector('#stiffness6 td.k6').dataset.value !== '' && "
                                 "document.getElementById('scene').dataset.ellipsoid === 'drawn'")
                if n == 0:  # the fit came: nothing moved
                    assert browser.evaluate(PLACES_JS) == before
                # the 6x6 status is the first status on the page; nothing of the one-axis fit is shown
                badges = browser.evaluate(BADGES_JS)
                assert [b[0] for b in badges] == ['stiffness6-level'], badges
                for hidden in ('xy', 'estimate', 'status', 'status-level', 'k-prediction'):
                    assert browser.evaluate(f"document.getElementById('{hidden}').offsetParent") is None, hidden
                shown = browser.evaluate('document.body.innerText')
                assert 'WARN' not in shown and 'nonlinear' not in shown and 'prediction' not in shown
                # the chosen row of K: fy by default, each entry with its interval and the model's
                row = browser.evaluate("[...document.querySelectorAll('#k6-row-table tr')].slice(1).map((r) => "
                                       "[...r.cells].map((c) => c.textContent))")
                assert [r[0] for r in row] == ['u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z']
                assert float(row[1][1]) == pytest.approx(measured[1, 1], rel=5e-4)
                assert row[1][5] == f'{100 * (measured[1, 1] / tangent[1, 1] - 1.0):.2f} %'
                # the statistical interval is the repeatability; no U on the wire for the 6x6 yet: said, not blank
                assert ' .. ' in row[1][2] and row[1][3] == 'not stated', row[1]
                assert check_texts(browser) > 100
                browser.screenshot(tmp_path / f'six_axis_{width}.png', full_page=True)
            finally:
                browser.close()
    SHOTS.mkdir(parents=True, exist_ok=True)
    for width, _ in SIZES:
        shutil.copy(tmp_path / f'six_axis_{width}.png', SHOTS / f'page_six_axis_{width}.png')
