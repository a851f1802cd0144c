"""``crane-stiffness campaign run``: a campaign's sessions played one after the other on the rig, unattended on the
simulated rig, with the operator's confirmation before each session on hardware; resumable.

Each session is the whole rig started as ``ros2 launch`` starts it (crane_stiffness.launcher.rig.run_rig: every node
its own process, the session recorder writing its own bag), with its set-up as parameters: the crane_model node
runs the **true** crane (``geometry.*`` of :attr:`~crane_stiffness.campaign.spec.SessionPlan.true`), the session
recorder records the **nominal** one as the rig's geometry and the session's place in the campaign as its
``campaign_entry`` (crane_stiffness.bag.session_metadata.CAMPAIGN_KEY: ``analysis_geometry: nominal``, the true crane,
what the operator confirmed); the program is the series' file with its levels scaled for the set-up.

The campaign directory ``DIR``::

    DIR/plan.json                 the sessions planned (and a fingerprint of them), the campaign file's text
    DIR/bags/<session>/           each session's bag
    DIR/sessions/<session>/       its program file, node logs and result.json (written last: the session is done)
    DIR/interrupted/<session>-N/  the partial bag of a session that was interrupted, kept aside

Run again with the same campaign file, ``run`` skips every session whose result.json exists and starts again the
one that was interrupted (its partial bag moved to interrupted/): a Ctrl-C or a crash loses no finished session.
A directory started by another campaign (a different plan) is refused.
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from crane_stiffness.campaign.errors import CampaignError
from crane_stiffness.campaign.session import RESULT_FILE, SessionRunner, session_program_text, utc
from crane_stiffness.campaign.spec import SERIES, Campaign, SessionPlan, plan_fingerprint, plan_sessions

PLAN_FILE = 'plan.json'
#: A confirmation: given the session and the instructions, return what the operator confirmed (or raise).
Confirm = Callable[[SessionPlan, str], dict[str, Any]]
#: A review after each session (crane_stiffness.campaign.verdict.Review): given the session, its result and whether
#: it can be run again now, return 'continue', 'repeat' or 'stop'.
Review = Callable[[SessionPlan, dict[str, Any], bool], str]


class CampaignInterrupted(CampaignError):
    """The campaign stopped before its end (Ctrl-C, the operator quit); the message says how far it got."""


@dataclass
class CampaignRun:
    """What a run did: sessions run now, skipped as done before, and their results."""

    out: Path
    planned: int
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    results: dict[str, dict[str, Any]] = field(default_factory=dict)
    repeated: list[str] = field(default_factory=list)
    """Sessions the operator had run again after their verdict (once per repeat)."""


def instructions(plan: SessionPlan, total: int) -> str:
    """What the operator sets up before a session on hardware, in words."""
    return (f'session {plan.index + 1}/{total} {plan.id}: {SERIES[plan.series]} series ({plan.series}); hang '
            f'W = {plan.weight:g} N, set the wires to l0 = {plan.l0:.4g} m (unloaded height {plan.height:.4g} m); '
            + ('program designed for this set-up (D-optimal, all six axes; the pose sensor measures)'
               if plan.program_text is not None else
               f'program {Path(plan.program).name} scaled by {plan.program_scale:.4g}')
            + '; leave the platform unloaded and still: the program tares the load cell and zeroes the LVDT at the '
              'unloaded state before its first step (load_program tare_services)')


def session_done(out: Path, plan: SessionPlan) -> bool:
    return (out / 'sessions' / plan.id / RESULT_FILE).is_file()


def prepare_campaign(out: Path, campaign: Campaign, plans: list[SessionPlan]) -> None:
    """Write the plan of a new campaign directory, or check that an existing one holds the same plan."""
    fingerprint = plan_fingerprint(plans)
    path = out / PLAN_FILE
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except ValueError as exc:
            raise CampaignError(f'{path}: unreadable ({exc}); give another --out') from None
        if old.get('fingerprint') != fingerprint:
            raise CampaignError(f'{out} holds campaign {old.get("campaign")!r} planned from {old.get("file")}, not '
                                f'the sessions of {campaign.path}: give another --out (or run that campaign file)')
        return
    out.mkdir(parents=True, exist_ok=True)
    data = {'campaign': campaign.name, 'file': str(campaign.path), 'fingerprint': fingerprint,
            'text': campaign.path.read_text(), 'true_differs': campaign.true_differs,
            'sessions': [p.to_dict() for p in plans]}
    tmp = path.with_suffix('.tmp')
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)


def read_plan(out: str | os.PathLike) -> dict[str, Any]:
    """The plan.json of a campaign directory (CampaignError when there is none)."""
    path = Path(out) / PLAN_FILE
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise CampaignError(f'{out}: not a campaign directory (no {PLAN_FILE}; `crane-stiffness campaign run` makes '
                            'one)') from None


def sim_time_arguments(arguments: Mapping[str, str] | None, hardware: bool) -> dict[str, str]:
    """The rig arguments of a campaign's sessions: simulated time at the highest pace for the simulated rig (its
    sensors simulated, no drivers) unless ``arguments`` set use_sim_time; wall-clock time with hardware."""
    out = dict(arguments or {})
    simulated = (not hardware and out.get('transport', 'sim') == 'sim'
                 and str(out.get('sim_sensors', 'true')).lower() in ('true', '1'))
    if simulated and 'use_sim_time' not in out:
        out['use_sim_time'] = 'true'
        out.setdefault('real_time_factor', 'max')
    return out


def session_domains(env: Mapping[str, str], jobs: int) -> list[int]:
    """The ROS domain of each of ``jobs`` sessions run side by side: ROS_DOMAIN_ID (0 if unset) and the next ones
    (simulated time keeps one ``/clock`` per domain, so two rigs never share one)."""
    base = int(env.get('ROS_DOMAIN_ID', '0') or 0)
    domains = [base + k for k in range(jobs)]
    if domains[-1] > 232:
        raise CampaignError(f'--jobs {jobs} with ROS_DOMAIN_ID={base} needs domains up to {domains[-1]}; DDS has '
                            '0..232: choose a lower ROS_DOMAIN_ID or fewer jobs')
    return domains


def default_jobs(arguments: Mapping[str, str], hardware: bool) -> int:
    """Sessions run side by side by default: on simulated time one more than the machine has cores (each session's
    numbers do not depend on the machine's load, and a session spends much of its wall time starting its processes
    and waiting for DDS to match them), at most 4; else one."""
    if hardware or str(arguments.get('use_sim_time', 'false')).lower() != 'true':
        return 1
    from crane_stiffness.campaign.parallel import default_workers
    return min(4, default_workers() + 1)


def run_campaign(campaign: Campaign, out: str | os.PathLike, *, hardware: bool = False,
                 confirm: Confirm | None = None, arguments: Mapping[str, str] | None = None,
                 progress: bool = True, ready_timeout_s: float = 120.0, jobs: int | None = None,
                 on_session: Callable[[SessionPlan], None] | None = None, scheduler: str | None = None,
                 rig: str | None = None, review: Review | None = None, load_application: str | None = None,
                 settle_s: float = 2.0, operator: str = '') -> CampaignRun:
    """Run every session of ``campaign`` not done yet in ``out`` (see the module docstring).

    Args:
        hardware: stop before each session for ``confirm`` (the operator); the crane model runs the nominal crane.
        confirm: how the operator confirms (hardware); default a prompt at the terminal.
        arguments: other rig launch arguments (transport, sim_sensors, drivers, use_sim_time, ...). The simulated
            rig runs on simulated time as fast as it keeps up (use_sim_time:=true, real_time_factor:=max) unless
            they say otherwise: the same results at any load, and faster than real time on a quiet machine.
        progress: a progress bar over the whole campaign on stderr.
        jobs: sessions run side by side, each rig in a ROS domain of its own (:func:`session_domains`); default
            :func:`default_jobs` (cores + 1, at most 4, on simulated time). Only simulated time gives the same
            numbers at any load, so more than one job needs it; hardware runs one session at a time.
        on_session: called before each session is started (tests use it to interrupt a campaign).
        scheduler: a Dask scheduler's address (``tcp://host:8786``): the sessions run on its workers, each rig on
            its worker's machine, and come back into ``out`` (crane_stiffness.campaign.distributed); simulated
            rig on simulated time only. ``jobs`` does not apply (the cluster's workers and threads decide).
        rig: 'host' runs each session's simulated nodes in one process that stays up between sessions (one per
            job, crane_stiffness.launcher.rig_host: the same bags and numbers, without starting eight processes per
            session); 'processes' starts them as ``ros2 launch`` does, every session anew. Default
            :func:`default_rig`.
        review: called after each session, before the next set-up (the command line's shows the session's verdict,
            crane_stiffness.campaign.verdict.Review): 'repeat' runs the session again (one session at a time only;
            on hardware after a new confirmation), 'stop' stops the campaign (CampaignInterrupted).
        load_application, settle_s, operator: how the load reaches the crane and who runs the test
            (:func:`load_program_parameters`).

    Raises:
        CampaignError: ``out`` holds another campaign; a true crane with --hardware; jobs without simulated time.
        CampaignInterrupted: Ctrl-C or the operator stopped it (the finished sessions are kept).
        RosRunError: a node failed (its log tail in the message).
    """
    from crane_stiffness.launcher import rosrun
    from crane_stiffness.params.files import share_dir

    from crane_stiffness.rosnode.discovery import use_quick_discovery
    use_quick_discovery()  # the observers find the nodes as quickly as the nodes find each other
    out = Path(out)
    arguments = sim_time_arguments(arguments, hardware)
    if hardware and campaign.true_differs:
        raise CampaignError(f'{campaign.path}: true.* describes a simulated crane; with --hardware the crane is the '
                            'real one: set true.wire_stiffness_factor and true.weight_factor to 1')
    jobs = default_jobs(arguments, hardware) if jobs is None else int(jobs)
    if jobs < 1:
        raise CampaignError(f'--jobs {jobs}: must be at least 1')
    if scheduler and default_jobs(arguments, hardware) == 1:
        raise CampaignError(f'--scheduler {scheduler}: sessions on a cluster need the simulated rig on simulated time '
                            '(the same numbers on any machine); run hardware and wall-clock sessions here')
    if jobs > 1 and default_jobs(arguments, hardware) == 1:
        raise CampaignError(f'--jobs {jobs}: sessions side by side need the simulated rig on simulated time (on the '
                            'wall clock they would take each other\'s cores and lose samples); use --jobs 1')
    rig = default_rig(arguments, hardware) if rig is None else rig
    if rig == 'host' and default_rig(arguments, hardware) != 'host':
        raise CampaignError('--rig host runs the simulated sensors on simulated time (use_sim_time:=true, '
                            'transport:=sim, no live view); this campaign needs --rig processes')
    if rig not in ('host', 'processes'):
        raise CampaignError(f'--rig {rig}: expected host or processes')
    plans = plan_sessions(campaign)
    prepare_campaign(out, campaign, plans)
    run = CampaignRun(out=out, planned=len(plans))
    todo = [p for p in plans if not session_done(out, p)]
    run.skipped = [p.id for p in plans if session_done(out, p)]
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    jobs = max(1, min(jobs, len(todo)))
    domains = session_domains(env, jobs)
    session = SessionRunner(campaign, out, hardware, arguments, env, share_dir() / 'config',
                             rosrun.node_executables(), ready_timeout_s, rig=rig,
                             load_program=load_program_parameters(arguments, hardware, load_application, settle_s,
                                                                  operator))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(plans), initial=len(run.skipped), desc=f'campaign {campaign.name}', unit='session',
                   mininterval=0.5,
                   file=sys.stderr, bar_format='{l_bar}{bar}| {n:.1f}/{total} sessions [{elapsed}<{remaining}] '
                   '{postfix}')
    done_before = len(run.skipped)
    fractions: dict[str, float] = {}  # sessions under way: the program's progress (0 .. 1)
    if hardware and session.load_program.get('load_application') == 'operator':
        def say(session_id: str, text: str) -> None:
            # (the program holds until the measured load settles at the level, or /load_program/confirm is called)
            line = f'  {session_id}: {text}'
            if bar is not None:
                bar.write(line, file=sys.stderr)
            else:
                print(line, file=sys.stderr, flush=True)
        session.operator_prompt = say

    def show() -> None:
        if bar is None:
            return
        value = round(done_before + len(run.ran) + 0.99 * sum(fractions.values()), 2)
        if value != bar.n:
            bar.n = value
            bar.set_postfix_str(', '.join(fractions) or '', refresh=False)
            bar.refresh()

    def finished(plan: SessionPlan, result: dict[str, Any], repeatable: bool = False) -> str:
        fractions.pop(plan.id, None)
        run.ran.append(plan.id)
        run.results[plan.id] = result
        show()
        decision = 'continue' if review is None else review(plan, result, repeatable)
        if decision == 'repeat' and repeatable:
            run.ran.remove(plan.id)
            run.repeated.append(plan.id)
            return decision
        if decision == 'stop':
            raise CampaignInterrupted(f'stopped by the operator after session {plan.id} (NOT OK; its verdict is in '
                                      f'{out / "sessions" / plan.id / "verdict.json"}): {done_before + len(run.ran)} '
                                      f'of {len(plans)} sessions done in {out}; run the same command again to go on '
                                      'with the next one')
        return 'continue'

    def finished_once(plan: SessionPlan, result: dict[str, Any]) -> None:
        finished(plan, result, False)  # (sessions side by side or on a cluster: not run again)

    try:
        if scheduler:
            from crane_stiffness.campaign.distributed import run_on_cluster
            texts = {plan.id: session_program_text(plan) for plan in todo}
            run_on_cluster(campaign, out, todo, texts, arguments, scheduler, ready_timeout_s, on_session,
                           finished_once, rig)
        elif jobs == 1:
            for plan in todo:
                decision = 'repeat'
                while decision == 'repeat':  # (the session again when its review says so: it is set aside first)
                    if on_session is not None:
                        on_session(plan)
                    confirmed = None
                    if hardware:
                        confirmed = (confirm or terminal_confirm)(plan, instructions(plan, len(plans)))
                    fractions[plan.id] = 0.0
                    decision = finished(plan, session.run(plan, confirmed, domains[0],
                                                          _tracker(fractions, plan.id, show)), True)
        else:
            _run_side_by_side(session, todo, domains, on_session, fractions, show, finished_once)
    except KeyboardInterrupt:
        raise CampaignInterrupted(f'interrupted: {done_before + len(run.ran)} of {len(plans)} sessions done in '
                                  f'{out}; run the same command again to resume') from None
    finally:
        session.close()
        if bar is not None:
            bar.close()
    return run


#: The Trigger services that tare the load cell and zero the LVDT, by transport (rig argument).
TARE_SERVICES = {'sim': ['/load_cell/tare', '/lvdt/zero'], 'drivers': ['/netft/tare', '/modbus_lvdt/zero']}


def load_program_parameters(arguments: Mapping[str, str], hardware: bool, load_application: str | None,
                            settle_s: float, operator: str) -> dict[str, Any]:
    """load_program's parameters for every session: how the load reaches the crane (default: the simulated crane,
    ``model``; with hardware ``operator``, a person at each new level) and, with hardware, the tare and zero at the
    unloaded state before the first step (the sensors of the rig's ``transport``) and who runs the test. An operator
    level is confirmed by ``/load_program/confirm`` or by the measured load settling within its tolerance for
    ``settle_s`` [s] (0: by the call only)."""
    application = load_application or ('operator' if hardware else 'model')
    if application not in ('model', 'operator', 'actuator'):
        raise CampaignError(f'--load-application {application}: expected model, operator or actuator')
    if application != 'model' and not hardware:
        raise CampaignError(f'--load-application {application}: a person or an actuator applies the load on a real '
                            'rig only: add --hardware (the simulated crane applies it itself)')
    if not settle_s >= 0.0:
        raise CampaignError(f'--settle-s {settle_s}: must be >= 0 [s]')
    if not hardware:
        return {}
    params: dict[str, Any] = {'load_application': application, 'operator': operator_name(operator),
                              'tare_services': TARE_SERVICES.get(str(arguments.get('transport', 'sim')), [])}
    if application == 'operator':
        params['operator_settle_s'] = float(settle_s)
    return params


def default_rig(arguments: Mapping[str, str], hardware: bool) -> str:
    """'host' for the simulated rig on simulated time with the simulated sensors and no live view (the nodes a
    rig host runs); else 'processes'."""
    sim_time = str(arguments.get('use_sim_time', 'false')).lower() == 'true'
    plain = (str(arguments.get('transport', 'sim')) == 'sim' and str(arguments.get('sim_sensors', 'true')) == 'true'
             and str(arguments.get('live_view', 'false')).lower() != 'true')
    return 'host' if sim_time and plain and not hardware else 'processes'


def _tracker(fractions: dict[str, float], session: str, show: Callable[[], None] | None = None
             ) -> Callable[[float], None]:
    """A progress callback that keeps ``session``'s program progress (0 .. 1) in ``fractions`` (then ``show()``)."""
    def follow(fraction: float) -> None:
        fractions[session] = min(max(fraction, 0.0), 1.0)
        if show is not None:
            show()
    return follow


def _run_side_by_side(session: 'SessionRunner', todo: list[SessionPlan], domains: list[int],
                      on_session: Callable[[SessionPlan], None] | None, fractions: dict[str, float],
                      show: Callable[[], None], finished: Callable[[SessionPlan, dict[str, Any]], None]) -> None:
    """The sessions of ``todo`` in worker threads, one per domain, in plan order as workers come free. Ctrl-C (in
    this, the main thread) stops every session under way, its nodes ended as at the end of a session; the sessions
    finished are kept. The first session that fails stops the others and its error is raised."""
    import threading
    from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait

    stop = threading.Event()
    free = list(domains)
    pending = list(todo)
    running: dict[Future, tuple[SessionPlan, int]] = {}
    with ThreadPoolExecutor(max_workers=len(domains), thread_name_prefix='session') as pool:
        try:
            while pending or running:
                while pending and free:
                    plan = pending.pop(0)
                    if on_session is not None:
                        on_session(plan)
                    domain = free.pop(0)
                    fractions[plan.id] = 0.0
                    # (the progress bar is drawn by this thread only, so the workers just keep their fraction)
                    future = pool.submit(session.run, plan, None, domain, _tracker(fractions, plan.id), stop.is_set)
                    running[future] = (plan, domain)
                done, _ = wait(running, timeout=0.5, return_when=FIRST_COMPLETED)
                show()
                for future in done:
                    plan, domain = running.pop(future)
                    free.append(domain)
                    finished(plan, future.result())  # a failed session raises here: the others are stopped below
        except BaseException:
            stop.set()  # every session under way stops its nodes; wait for them (the pool's exit) before leaving
            raise


def operator_name(given: str = '') -> str:
    """Who confirms: ``given`` (``campaign run --operator``), else the login name of the process ($USER, $LOGNAME,
    or the account's name), '' only when none is known."""
    if given:
        return given
    import getpass
    try:
        return getpass.getuser()
    except (OSError, KeyError):  # no $USER / $LOGNAME and a uid without a passwd entry (a bare container)
        return ''


def terminal_confirm(plan: SessionPlan, text: str, operator: str = '') -> dict[str, Any]:
    """Ask at the terminal: the operator types y when the set-up is done (q stops the campaign); ``operator``: who
    (default the login name, :func:`operator_name`), recorded with the confirmation."""
    print(f'\n{text}', file=sys.stderr)
    while True:
        try:
            answer = input('set up done? [y = run it / q = stop the campaign] ').strip().lower()
        except EOFError:
            raise CampaignInterrupted(f'no confirmation for session {plan.id} (end of input)') from None
        if answer in ('y', 'yes'):
            return {'how': 'terminal', 'at_utc': utc(), 'user': operator_name(operator), 'instructions': text,
                    'weight': plan.weight, 'l0': plan.l0}
        if answer in ('q', 'quit'):
            raise CampaignInterrupted(f'stopped by the operator before session {plan.id}')


def service_confirm(timeout_s: float | None = None, operator: str = '') -> Confirm:
    """A confirmation by a ``/campaign/continue`` service call (std_srvs/Trigger), so a second machine can confirm:
    the node ``campaign`` offers it while waiting; the call's answer repeats the instructions. The record's ``user``
    is ``operator`` (default the login name of this process: the call itself does not say who made it)."""
    def confirm(plan: SessionPlan, text: str) -> dict[str, Any]:
        import rclpy
        from std_srvs.srv import Trigger
        print(f'\n{text}\nwaiting for a call of /campaign/continue (std_srvs/srv/Trigger) ...', file=sys.stderr,
              flush=True)
        ctx = rclpy.Context()
        rclpy.init(args=[], context=ctx)  # not sys.argv: --rig-arg NAME:=VALUE there warns as a remap rule
        node = rclpy.create_node('campaign', context=ctx)
        called: dict[str, Any] = {}

        def on_call(request: Any, response: Any) -> Any:
            called.update({'how': 'service /campaign/continue', 'at_utc': utc(), 'user': operator_name(operator),
                           'instructions': text,
                           'weight': plan.weight, 'l0': plan.l0})
            response.success = True
            response.message = f'running {text}'
            return response
        node.create_service(Trigger, '~/continue', on_call)
        from rclpy.executors import SingleThreadedExecutor
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        try:
            while not called:
                if deadline is not None and time.monotonic() > deadline:
                    raise CampaignInterrupted(f'no /campaign/continue call for session {plan.id} in {timeout_s} s')
                executor.spin_once(timeout_sec=0.1)
            end = time.monotonic() + 1.5  # the answer reaches the caller before the node goes (slow when loaded)
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
        return called
    return confirm
