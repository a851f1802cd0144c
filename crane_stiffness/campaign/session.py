"""One session of a campaign on the rig: its program file, its place in the campaign as the recorder stores it,
the rig run in its ROS domain and its ``result.json`` (written last: the session is done). The local runner
(:mod:`.runner`) and a Dask worker (:mod:`.distributed`) run a session through the same :class:`SessionRunner`."""
from __future__ import annotations

import json
from functools import partial
import os
import shutil
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Mapping

from crane_stiffness.campaign.errors import CampaignError
from crane_stiffness.campaign.spec import Campaign, SessionPlan, scaled_program_text

#: How a session's rig runs (SessionRunner's ``rig``).
RIGS = ('processes', 'host', 'host-here')

RESULT_FILE = 'result.json'
#: What a hardware session's record says of crane_model's outputs in its bag.
MODEL_OUTPUTS_ON_HARDWARE = ('predictions of the nominal model, not measurements: /crane/applied_wrench is the '
                             'commanded load as the model takes it, /crane/platform_pose the pose the model predicts '
                             'for it; the measurements are the sensors\' topics')


def session_program_text(plan: SessionPlan) -> str:
    """The program file a session plays: its designed program, or the series' file with its levels scaled."""
    return plan.program_text if plan.program_text is not None else scaled_program_text(Path(plan.program),
                                                                                        plan.program_scale)


def campaign_entry(campaign: Campaign, plan: SessionPlan, hardware: bool, confirmed: Mapping[str, Any] | None,
                   load_application: str = 'model') -> dict[str, Any]:
    """The session's place in the campaign as the recorder stores it (session_metadata.CAMPAIGN_KEY). On hardware
    it says that crane_model's outputs in the bag (/crane/applied_wrench, /crane/platform_pose) are the nominal
    model's predictions, not measurements, and how the load reached the crane (``load_application``)."""
    entry: dict[str, Any] = {
        'campaign': campaign.name, 'file': str(campaign.path), 'session': plan.id, 'index': plan.index,
        'series': plan.series, 'weight': plan.weight, 'l0': plan.l0, 'height': plan.height, 'repeat': plan.repeat,
        'program_scale': plan.program_scale, 'rig': 'hardware' if hardware else 'simulated',
        'seeds': None if hardware else plan.seeds,
        'analysis_geometry': 'nominal'}
    if not hardware:
        entry['true_geometry'] = dict(plan.true)
    else:
        entry['load_application'] = load_application
        entry['model_outputs'] = MODEL_OUTPUTS_ON_HARDWARE
    if confirmed is not None:
        entry['confirmed'] = dict(confirmed)
    return entry


def set_aside(out: Path, plan: SessionPlan) -> None:
    """A session started before and not finished: its partial bag and logs moved together to interrupted/<id>-N/
    (bags/ and sessions/ in it, N counting the attempts set aside)."""
    parts = [part for part in (out / 'bags' / plan.id, out / 'sessions' / plan.id) if part.exists()]
    if not parts:
        return
    n = 1
    while (out / 'interrupted' / f'{plan.id}-{n}').exists():
        n += 1
    target = out / 'interrupted' / f'{plan.id}-{n}'
    target.mkdir(parents=True)
    for part in parts:
        shutil.move(str(part), str(target / part.parent.name))


class SessionRunner:
    """One session of a campaign on the rig: its folder, program and parameters, the rig run, its result.json."""

    def __init__(self, campaign: Campaign, out: Path, hardware: bool, arguments: Mapping[str, str],
                 env: Mapping[str, str], share: Path, executables: Path | None, ready_timeout_s: float,
                 program_texts: Mapping[str, str] | None = None, rig: str = 'processes', here: Any = None,
                 load_program: Mapping[str, Any] | None = None) -> None:
        self.campaign, self.out, self.hardware, self.arguments = campaign, out, hardware, dict(arguments)
        self.env, self.share, self.executables, self.ready_timeout_s = dict(env), share, executables, ready_timeout_s
        #: Program files by session id, made where the plan was made (a Dask worker gets them with the task).
        self.program_texts = dict(program_texts or {})
        if rig not in RIGS:
            raise CampaignError(f'rig {rig!r}: expected one of {", ".join(RIGS)}')
        #: 'processes': every session starts the rig's nodes as processes, as ros2 launch does; 'host': the
        #: simulated nodes of each session in one process that stays up (crane_stiffness.launcher.rig_host), one per
        #: ROS domain, in its own process (:attr:`hosts`), or with ``rig='host-here'`` on ``here``, a RigHost of this
        #: process that the caller keeps (a Dask worker's).
        self.rig = rig
        #: Parameters of load_program set on top of the program file (how the load is applied, the tare).
        self.load_program = dict(load_program or {})
        #: Called with (session id, instruction) when load_program waits for the operator (a rig of processes: the
        #: hardware's): the campaign shows it at the terminal beside the set-up prompt.
        self.operator_prompt: Callable[[str, str], None] | None = None
        self.hosts: dict[int, Any] = {}
        self._hosts_lock = threading.Lock()
        self._here = here
        if rig == 'host-here' and here is None:
            raise CampaignError("rig 'host-here' needs the RigHost to run on")

    def close(self) -> None:
        """End the rig hosts this runner started."""
        with self._hosts_lock:
            hosts, self.hosts = list(self.hosts.values()), {}
        for host in hosts:
            host.close()

    def _outcome(self, folder: Path, program: Path, plan: SessionPlan, domain: int, overrides: dict[str, Any],
                 progress: Callable[[float], None], should_stop: Callable[[], bool] | None) -> dict[str, Any]:
        """The rig run of one session, as :func:`crane_stiffness.launcher.host_process.outcome` gives it."""
        from crane_stiffness.launcher.host_process import HostProcess, outcome
        from crane_stiffness.launcher.rig import run_rig

        kwargs: dict[str, Any] = dict(share=self.share, out=folder, program=str(program), session=plan.id,
                      ready_timeout_s=self.ready_timeout_s, overrides=overrides, bags=self.out / 'bags',
                      arguments=self.arguments)
        if self.rig == 'processes':
            say = self.operator_prompt
            summary, observer, startup_s, _ = run_rig(env=self.env, executables=self.executables, progress=progress,
                                                      domain_id=domain, should_stop=should_stop,
                                                      prompt=None if say is None else partial(say, plan.id), **kwargs)
            return outcome(summary, observer, startup_s)
        if self.rig == 'host-here':
            summary, observer, startup_s, _ = self._here.run(progress=progress, should_stop=should_stop, **kwargs)
            return outcome(summary, observer, startup_s)
        with self._hosts_lock:
            host = self.hosts.get(domain)
            if host is None:
                host = self.hosts[domain] = HostProcess(domain, self.env)
        return host.run(progress=progress, should_stop=should_stop, **kwargs)

    def run(self, plan: SessionPlan, confirmed: Mapping[str, Any] | None, domain: int,
            progress: Callable[[float], None], should_stop: Callable[[], bool] | None = None,
            attempts: int = 2) -> dict[str, Any]:
        """Run ``plan`` in ROS domain ``domain`` and write its result.json; the result. A rig that did not start
        its program (RigStartError: nothing measured) is started again, ``attempts`` times in all."""
        from crane_stiffness.launcher.rig import decode_values
        from crane_stiffness.launcher.rosrun import RigStartError

        out = self.out
        for attempt in range(1, attempts + 1):
            set_aside(out, plan)
            folder = out / 'sessions' / plan.id
            folder.mkdir(parents=True)
            program = folder / 'program.yaml'
            program.write_text(self.program_texts[plan.id] if plan.id in self.program_texts else
                               session_program_text(plan))
            entry = campaign_entry(self.campaign, plan, self.hardware, confirmed,
                                   str(self.load_program.get('load_application', 'model')))
            model = plan.nominal if self.hardware else plan.true
            seeds = {} if self.hardware or plan.seeds is None else plan.seeds
            # (the campaign's sensor parameters on the simulated rig only: a real sensor has its own truth)
            extra = {} if self.hardware else (plan.parameters or {})
            overrides = {**extra, **{node: {**extra.get(node, {}), 'seed': seed} for node, seed in seeds.items()},
                         'crane_model': dict(model),
                         'session_recorder': {**plan.nominal, 'campaign_entry': _yaml_string(json.dumps(entry)),
                                              'notes': _yaml_string(f'campaign {self.campaign.name}, session '
                                                                    f'{plan.id}' + (
                                                  f'; crane_model outputs: {MODEL_OUTPUTS_ON_HARDWARE}'
                                                  if self.hardware else ''))}}
            if self.load_program:
                overrides['load_program'] = dict(self.load_program)
            started = time.time()
            try:
                ran = self._outcome(folder, program, plan, domain, overrides, progress, should_stop)
            except RigStartError as exc:
                if attempt == attempts:
                    raise
                print(f'\nsession {plan.id}: the rig did not start ({exc}); starting it again (attempt {attempt + 1} '
                      f'of {attempts}; the first is kept in {out / "interrupted"})', file=sys.stderr, flush=True)
                continue
            break
        result = {'session': plan.id, 'plan': plan.to_dict(), 'campaign_entry': entry,
                  'time': 'simulated' if self.arguments.get('use_sim_time') == 'true' else 'wall',
                  'wall_s': round(time.time() - started, 3), 'attempts': attempt,
                  'ros_domain_id': ran['summary'].get('ros_domain_id', domain),  # (a domain in use: the next free)
                  'bag': str(out / 'bags' / plan.id), 'started_utc': utc(started), 'finished_utc': utc(),
                  'rig': 'processes' if self.rig == 'processes' else 'host',
                  'startup_s': ran['startup_s'], 'estimate': decode_values(ran['values']) if ran['values'] else None,
                  'status': ran['summary']['status'], 'node_exit_codes': ran['summary']['node_exit_codes'],
                  'recording': ran['summary'].get('recording'),
                  # The six-axis fit's last K (quantity × row × column, /stiffness6/stiffness) and status, if it ran.
                  'stiffness6': ran['stiffness6'],
                  'status6': None if ran['status6'] is None else
                  {'level': ran['status6'][0], 'message': ran['status6'][1], 'values': ran['status6'][2]}}
        tmp = folder / (RESULT_FILE + '.tmp')
        tmp.write_text(json.dumps(result, indent=1, allow_nan=True))
        os.replace(tmp, folder / RESULT_FILE)
        return result


def _yaml_string(text: str) -> str:
    """``text`` as a YAML single-quoted scalar: a ``-p name:=value`` override is read as YAML, and a JSON object
    unquoted would be a mapping, not the string parameter."""
    return "'" + text.replace("'", "''") + "'"


def utc(t: float | None = None) -> str:
    return datetime.fromtimestamp(time.time() if t is None else t, tz=timezone.utc).isoformat(timespec='seconds')
