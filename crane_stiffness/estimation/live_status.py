"""What the live estimator says about its inputs: every message accounted (the node's final counters) and the input
status of /stiffness/estimate. Functions of a :class:`~crane_stiffness.estimation.live.LiveStiffness` (its private
state: they are its own reports, kept apart for the module's size). Pure Python, no ROS."""
from __future__ import annotations

import math
from dataclasses import fields
from typing import TYPE_CHECKING

from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE
from crane_stiffness.status import OK, WARN, status_value

if TYPE_CHECKING:
    from crane_stiffness.estimation.live import LiveStiffness


def accounting(live: LiveStiffness) -> dict[str, int]:
    """Every message accounted (the node's final counters): per stream received = dropped (input checks) +
    passed_checks, and passed_checks = out_of_order + non_finite + stale + unmatched + discarded + pending +
    paired; pairs = fitted + rejected_command + non_finite; commands received = used + rejected + dropped."""
    out = {f.name: getattr(live.counters, f.name) for f in fields(live.counters)}
    sc = live._sync.counters
    out['pairs'] = sc.pairs
    for stream, counters in ((FORCE, sc.force), (DISPLACEMENT, sc.displacement)):
        for f in fields(counters):
            # the pairing's 'received' are the samples that passed the input checks (not the messages received)
            key = f'{stream}_passed_checks' if f.name == 'received' else f'{stream}_{f.name}'
            out[key] = getattr(counters, f.name)
        out[f'{stream}_pending'] = live._sync.pending(stream)
    return out


def input_report(live: LiveStiffness, consumer: str = '', now_s: float = math.nan
             ) -> tuple[int, str, list[tuple[str, str]]]:
    """Input health: (level, message, key/values); ERROR if a stream is silent (``now_s``: node clock, s), WARN
    if a rejected command is in force, a stream lost too many samples, or samples were dropped, out of order,
    stale or lost in a dropout since this ``consumer``'s previous call."""
    c = live.counters
    sc = live._sync.counters
    problems = {
        'dropped': c.dropped,
        'out_of_order': sc.total('out_of_order'),
        'stale': sc.total('stale'),
        'dropouts': sc.total('dropouts'),
    }
    snapshot = tuple(problems.values())
    previous = live._last_report.get(consumer, (0,) * len(snapshot))
    live._last_report[consumer] = snapshot
    new = {k: now - before for (k, now), before in zip(problems.items(), previous) if now > before}
    pairs = [(f.name, str(getattr(c, f.name))) for f in fields(c)]
    pairs += [('pairs', str(sc.pairs))]
    for stream, counters in ((FORCE, sc.force), (DISPLACEMENT, sc.displacement)):
        pairs += [(f'{stream}.{f.name}', str(getattr(counters, f.name))) for f in fields(counters)]
    for stream, health in live.health.items():
        pairs += [(f'{stream}.received_fraction', status_value(health.received_fraction())),
                  (f'{stream}.silent_s', status_value(health.silent_for(now_s)))]
    pairs += [('segment', str(c.segments)), ('segment_reason', live._segment_reason)]
    pairs += [('newest_pair_stamp', status_value(live._newest_stamp))]
    pairs += [(f'lag_{name}_ms', status_value(value * 1e3)) for name, value in (
        ('p50', live.lag.percentile(50)), ('p99', live.lag.percentile(99)), ('max', live.lag.max_s))]
    pairs += [('lag_n', str(live.lag.n))]
    pairs += live._delay.values()
    level, reasons = live.input_problems(now_s)
    if new:
        level = max(level, WARN)
        reasons.append('since last report: ' + ', '.join(f'{v} {k}' for k, v in new.items()))
    if reasons:
        return level, '; '.join(reasons), pairs
    return OK, f'{sc.pairs} pairs, {c.pairs_fitted} fitted', pairs


__all__ = ['accounting', 'input_report']
