"""The live estimator's pairing and branch labelling for whole recorded streams at once (numpy): the pairs
:class:`~crane_stiffness.estimation.live.LiveStiffness` would fit and the branch of each, composed of the vectorised
forms that sit beside each streaming rule (:mod:`~crane_stiffness.estimation.inputs`,
:func:`~crane_stiffness.estimation.sync.pair_by_stamp`, :func:`~crane_stiffness.estimation.sync.pair_by_interpolation`,
:func:`~crane_stiffness.estimation.branch.branch_labels`). ``test/estimation/test_live_estimate.py`` pins it to the
streaming
estimator. Pure numpy, no ROS.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crane_stiffness.estimation.branch import branch_labels
from crane_stiffness.estimation.inputs import CommandSeries, Samples, stream_health_of
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.sync import FORCE, pair_by_interpolation, pair_by_stamp, pair_stamp


@dataclass(frozen=True)
class LivePairs:
    """The pairs :class:`LiveStiffness` fits from whole recorded streams (:func:`live_pairs`), in stamp order."""

    stamp: np.ndarray
    """Pair stamps, s."""
    force: np.ndarray
    displacement: np.ndarray
    loading: np.ndarray
    """The branch each pair is fitted to: True for loading."""
    fit_log: np.ndarray
    """When the live estimator fits each pair: the arrival (log) time of the later of its two samples, ns."""
    counters: dict[str, float]
    """The pairing's counters (:func:`~crane_stiffness.estimation.sync.pair_by_stamp` or
    :func:`~crane_stiffness.estimation.sync.pair_by_interpolation`), and each stream's received fraction (float)."""
    late_rejection_log: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """When a rejected command reached the live estimator after pairs stamped under it were fitted (it WARNs until
    they leave its windows; :func:`late_rejections`), log time ns, ascending."""


def late_rejections(commands: CommandSeries | None, stamp: np.ndarray, fit_log: np.ndarray) -> np.ndarray:
    """The arrival (log) times, ns, of the rejected commands (absurd, or the model's) that reached the live
    estimator when a pair stamped at or after the command's stamp was already fitted
    (``LiveStiffness._rejected_late``). ``stamp``/``fit_log``: the pairs fitted (s; ns). A command and a pair at the
    same log time: the command first (the node takes commands before sensor messages)."""
    if commands is None or commands.rejected is None or not commands.rejected.any() or stamp.size == 0:
        return np.zeros(0, np.int64)
    arrival = commands.arrival_ns
    assert arrival is not None  # known whenever rejected is
    rej = np.flatnonzero(commands.rejected)
    by_log = np.argsort(fit_log, kind='stable')
    newest = np.maximum.accumulate(stamp[by_log])  # the newest stamp fitted, by the pairs' fit order
    upto = np.searchsorted(fit_log[by_log], arrival[rej], side='left')  # pairs fitted before it came
    late = (upto > 0) & (newest[np.maximum(upto - 1, 0)] >= commands.stamp[rej])
    return np.sort(arrival[rej][late].astype(np.int64))


def live_pairs(settings: LiveSettings, force: Samples, displacement: Samples,
               commands: CommandSeries | None) -> LivePairs:
    """What :class:`LiveStiffness` pairs and the branch it fits each pair to, for whole recorded streams that passed
    the input checks (:func:`~crane_stiffness.estimation.inputs.checked_samples`), vectorized. Pairs made while a
    rejected command was in force are left out (counted as ``pairs_rejected_command``)."""
    s = settings
    if s.interpolated is None:
        nearest = pair_by_stamp(force.stamp, force.arrival_ns, displacement.stamp, displacement.arrival_ns, s.slop_s,
                                s.max_age_s)
        pairing_counters = nearest.counters
        fi, di = nearest.force_index, nearest.displacement_index
        stamp = pair_stamp(force.stamp[fi], displacement.stamp[di])
        fit_log = np.maximum(force.arrival_ns[fi], displacement.arrival_ns[di])
        value, disp_value = force.value[fi], displacement.value[di]
    else:
        fast = s.interpolated
        interp = pair_by_interpolation(force.stamp, force.arrival_ns, displacement.stamp, displacement.arrival_ns,
                                       fast, (force if fast == FORCE else displacement).value,
                                       s.max_interpolation_gap_s, s.max_age_s)
        pairing_counters = interp.counters
        slow_samples, fast_samples = (displacement, force) if fast == FORCE else (force, displacement)
        si = interp.slow_index
        stamp = interp.stamp
        # A pair forms once its slow sample and the fast sample closing its bracket have both arrived.
        fit_log = np.maximum(slow_samples.arrival_ns[si], fast_samples.arrival_ns[interp.fast_index])
        slow_value = slow_samples.value[si]
        value, disp_value = (interp.fast_value, slow_value) if fast == FORCE else (slow_value, interp.fast_value)
    counters: dict[str, float] = dict(pairing_counters)
    if commands is not None:
        rejected = commands.rejected_at(stamp, fit_log)
        counters['pairs_rejected_command'] = int(rejected.sum())
        keep = ~rejected
        value, disp_value, stamp, fit_log = value[keep], disp_value[keep], stamp[keep], fit_log[keep]
    else:
        counters['pairs_rejected_command'] = 0
    load = value
    if commands is not None and s.branch_source == 'auto':
        held_load, held = commands.at(stamp, fit_log)
        load = np.where(held & np.isfinite(held_load), held_load, value)
    for name, samples in (('force', force), ('displacement', displacement)):
        counters[f'{name}_received_fraction'] = stream_health_of(samples.stamp,
                                                                 s.expected_period_s or None).received_fraction
    late = late_rejections(commands, stamp, fit_log)
    counters['late_rejections'] = int(late.size)
    return LivePairs(stamp, value, disp_value, branch_labels(load, s.hysteresis), fit_log, counters, late)


__all__ = ['LivePairs', 'late_rejections', 'live_pairs']
