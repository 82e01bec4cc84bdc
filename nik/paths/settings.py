"""The path solver's settings in one place: the reconfiguration threshold, the chains' pull towards a posture,
the restart and start budgets, the choice's limits and the posture search's sizes (radians, metres). Each stage that
reads them is described in :mod:`nik.paths.solve`."""

from __future__ import annotations

import math

#: Default threshold of a reconfiguration: a step (largest joint motion between two waypoints) above it is
#: reported and warned about, radians (10 degrees).
PATH_MAX_STEP = math.radians(10.0)
#: Redundant arms: each seed is moved this fraction of the way from the previous answer to the middle of the
#: joint ranges (the secondary objective: distance from the limits).
PATH_PULL = 0.02
#: ... by at most this much per joint and waypoint, radians (0.25 degrees).
PATH_PULL_CAP = math.radians(0.25)
#: Uniform restarts a waypoint that LM does not reach from its predecessor may draw (within reach only).
PATH_RESTARTS = 16
#: Closed-form arms with ``q_start``: the LM chain from ``q_start`` (each waypoint seeded by the previous answer) is
#: the answer when it reaches every waypoint inside the limits with no step above this (radians, 2 degrees) nor
#: above ``max_step``: its branch then never meets a limit, and there is nothing for the look-ahead to avoid. Else
#: the closed form's branches and the dynamic programming decide.
PATH_FOLLOW_STEP = math.radians(2.0)
#: Uniform starts at the first waypoint on an arm without a closed form and without ``q_start`` (beside the
#: network's hypotheses); distinct postures found become parallel chains.
PATH_STARTS = 8
#: Two first-waypoint answers closer than this (largest joint difference, radians) are one chain; a closed path's
#: last candidate this close to its first is on the same branch.
PATH_DEDUPE = 1e-2
#: Closed paths on closed-form arms: start candidates tried with the end pinned to their branch (when the free
#: choice does not close).
PATH_CLOSED_STARTS = 8
#: A closed path whose last row is within this of its first (largest joint difference, radians; modulo whole turns
#: on joints that wrap) is closed as it is; else :func:`_close_loop` closes it.
PATH_CLOSE_TOL = 1e-9
#: Most entries of one of the dynamic programming's ``(N, K, K)`` tables (with a free tool axis, K grows with the
#: sampled angles: :func:`_free_samples`).
PATH_DP_CELLS = 30_000_000
#: The last polish aims at this fraction of the tolerances (every reached waypoint whose error is above it), so that a
#: path's worst error is not at the threshold; a waypoint moves at most this fraction of ``max_step`` for it.
PATH_MARGIN = 0.5
#: The global search's tracks (arms without a closed form): each waypoint's seed moves this fraction of the way from
#: the previous answer towards the track's own posture ...
SEARCH_PULL = 0.05
#: ... by at most this much per joint and waypoint, radians (0.5 degrees).
SEARCH_PULL_CAP = math.radians(0.5)
#: The network's hypotheses (or uniform LM answers) per waypoint that the tracks drift towards (at the middle and the
#: last waypoint), and how far apart two of them must be (largest joint difference, radians) to count twice.
SEARCH_HYPOTHESES, SEARCH_DISTINCT = 4, math.radians(20.0)
#: The search's closed paths: distinct start candidates tried with the end pinned (:func:`_choose`; with ``q_start``
#: they all lie within ``max_step`` of it).
SEARCH_CLOSED_STARTS = 4
#: Among obstacles, how many times the search's choice is made again without the candidates that a colliding step
#: leads to (:func:`_free_steps`).
SEARCH_RECHOOSE = 3
#: Among obstacles, the waypoints (fractions of the path) whose answers the tracks drift towards.
SEARCH_ANCHORS = (0.25, 0.5, 0.75, 1.0)
#: Among obstacles, each posture also gets a fast track from the start: this pull, at most this per waypoint (radians,
#: 3 degrees, under the 7 degree steps a path may take): the self-motion swings away from a box met early.
SEARCH_FAST_PULL, SEARCH_FAST_CAP = 0.3, math.radians(3.0)
#: The search's answer replaces the chain's where it reaches more waypoints, closes a loop the chain leaves open, or
#: (else equal) cuts the largest step by more than this (radians, 0.5 degrees): on a tie the chain stays.
SEARCH_GAIN = math.radians(0.5)
#: The search runs where the chain takes a step above this (radians, 2 degrees, as :data:`PATH_FOLLOW_STEP`; or above
#: ``max_step``), misses a waypoint, collides, or leaves a loop open: below it a chain's path is taken as smooth (the
#: search costs about 30 chains; at 3 degrees, one panda circle in 19 more keeps a 3.1 degree step).
SEARCH_TRIGGER = math.radians(2.0)
