"""Approximate time pairing of the force and displacement streams by their header stamps.

A small stand-in for ``message_filters.ApproximateTimeSynchronizer`` (not available here) for exactly two streams,
``'force'`` and ``'displacement'``. Samples are ``(stamp_s, value)`` with the stamp in seconds (header time, not
arrival time) and the value a float or an array of floats (e.g. a wrench [fx, fy, fz, mx, my, mz] in N and N·m),
checked for NaN/Inf; any other object (a message, a label) is passed through unchecked.

Pairing rule: two samples are paired when their stamps differ by at most ``slop`` and each is the other's nearest
remaining sample (mutual nearest neighbours); each sample is used at most once and pairs come out in stamp order.
Deciding "nearest" may need the next sample of a stream, so a pair is usually emitted one sample period late; a
pair whose next sample never comes is emitted once the other stream is ``max_age`` ahead, or by :meth:`flush`.

Bookkeeping per stream (see :class:`StreamCounters`):

- out of order: a stamp older than the last accepted stamp of its stream (equal stamps are accepted); dropped.
- non-finite: a NaN/Inf stamp or value; dropped (a NaN value still counts as a sample for dropout detection).
- stale: a stamp older than the newest stamp of the other stream by more than ``max_age``; dropped. A queued sample
  that falls that far behind its own stream can no longer be paired and is dropped as unmatched.
- dropout: a gap between consecutive stamps larger than ``dropout_factor`` times the expected period (given, or
  estimated online from the gaps); the sample itself is kept.
- unmatched: a sample discarded because no partner within ``slop`` can exist.
- discarded: a sample still queued when the pairing restarted (:meth:`ApproximateTimeSync.restart`).

Every sample pushed is accounted: received = paired + out_of_order + non_finite + stale + unmatched + discarded +
pending (dropouts are flagged, not dropped).

Every push is amortised O(1) (deques, each sample enters and leaves once).

:func:`pair_by_stamp` is the same pairing over whole recorded streams at once (numpy), for the offline analysis of a
session: it finds the pairs and the out-of-order and stale counts :class:`ApproximateTimeSync` would, given the
samples in their order of arrival.

Interpolated pairing (:class:`InterpolatingSync`, vectorised :func:`pair_by_interpolation`) is the other rule, for
streams at different rates: each sample of the slower stream paired with the faster stream linearly interpolated at
its stamp; the same admission rule and accounting.
"""
from __future__ import annotations

from crane_stiffness.estimation.sync.base import (DISPLACEMENT, FORCE, STREAMS, Pair, StreamCounters, SyncCounters,
                                                  pair_stamp)
from crane_stiffness.estimation.sync.interpolate import InterpolatingSync, InterpolationResult, pair_by_interpolation
from crane_stiffness.estimation.sync.nearest import ApproximateTimeSync, PairResult, pair_by_stamp

__all__ = ['DISPLACEMENT', 'FORCE', 'STREAMS', 'ApproximateTimeSync', 'InterpolatingSync', 'InterpolationResult',
           'Pair', 'PairResult', 'StreamCounters', 'SyncCounters', 'pair_by_interpolation', 'pair_by_stamp',
           'pair_stamp']
