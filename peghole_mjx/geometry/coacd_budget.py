"""CoACD bounded: its piece count and time estimated in the first seconds, a refusal in one
line when the estimate exceeds the caps, else a run with a progress bar of a fraction.

CoACD (1.0.14) has no progress callback and no time limit: it runs in native code until it
ends, and ``peghole task make`` once spent ten minutes in it to learn that a hole part needed
300 pieces where the cap is 64 (issue 54). What it does have is a log: with the log level
``info`` it writes, to its standard output, ``iter k ---- waiting pool: P`` when it starts its
k-th round of cuts (``P`` parts still more concave than the threshold, each to be cut in two
by its tree search) and ``Merge Convex Hulls`` when no part is left to cut. Each part of a
round either is a finished piece or is cut in two, so the log tells exactly how many parts
have been searched and a lower bound on the pieces (:class:`CoacdLog`). CoACD runs in a child
process (:func:`~peghole_mjx.geometry.decompose.run_coacd`) whose standard output goes to a
file the parent reads while it waits.

1. :func:`estimate`: CoACD on the same mesh with the same options but a shorter tree search
   (:data:`COARSE`), given :data:`ESTIMATE_S` seconds for the pair. Its pieces estimate the
   full run's from above (:data:`COARSE_SLACK`); its searched parts times the full search's
   cost per part (the coarse cost per part times :data:`FULL_OVER_COARSE`) estimate the
   time. A coarse run that does not end in its budget gives lower bounds (the pieces
   finished or still waiting, the time spent so far scaled).
2. :func:`refusal`: one line naming the estimate and the options that would fit, when the
   pieces exceed the cap (``--max-hulls``) or the time exceeds ``max_s``.
3. :func:`run_bounded`: the full run with a bar of searched parts out of the estimated total
   (the total grows to what the log proves when the estimate was short; the bar ends at the
   merge), stopped with one line if it runs past ``max_s`` or its pieces pass the cap.

The vertex cap needs no estimate: CoACD decimates every piece to ``max_ch_vertex``.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, replace

from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.decompose import CoacdParams, run_coacd
from peghole_mjx.geometry.specs import MM

#: seconds from the start of ``task make`` within which a part for CoACD is refused or
#: accepted (issue 54's acceptance)
VERDICT_S = 30.0
#: seconds the coarse estimates of a pair may run in all (shared by the parts that need
#: CoACD), at most: less when the checks before them took longer (:func:`estimate_budget`)
ESTIMATE_S = 24.0
#: seconds kept for what follows the estimates before the verdict (the refusal's options)
VERDICT_MARGIN_S = 5.0
#: the shortest coarse run given a part (its lower bounds decide when it does not end)
MIN_ESTIMATE_S = 2.0
#: the coarse run's tree search: this cap on the user's parameters (decided 2026-12-05,
#: docs/research/models.md, bounded CoACD: fewer iterations keep CoACD's cuts and so its
#: pieces, a lower resolution or fewer nodes multiply the pieces)
COARSE = {"mcts_iterations": 30}
#: the full search's cost per searched part over the coarse one's at CoACD's defaults
#: (measured 2026-12-05, docs/research/models.md); scaled for other parameters by the ratio
#: of mcts_iterations x mcts_nodes (the tree search's evaluations)
FULL_OVER_COARSE = 6.0
#: a run is stopped once the pieces it has finished or still has to cut exceed the cap by
#: this factor: CoACD's merge took away 0-2 % of the pieces in the calibration runs
MERGE_SLACK = 1.1
#: a part is refused when its coarse estimate exceeds the cap by this factor: the coarse
#: search made 0-24 % more pieces than the full one in the calibration runs (2026-12-05)
COARSE_SLACK = 1.25
#: the most seconds ``task make`` lets CoACD run on one part unless told more (the full run
#: is stopped past it, and an estimate over it is refused up front)
COACD_MAX_S = 600.0

_POOL = re.compile(r"iter (\d+) -+ waiting pool: (\d+)")
_PROCESSING = re.compile(r"Processing \[([\d.]+)%\]")
_HULLS = re.compile(r"# Convex Hulls: (\d+)")


def estimate_budget(elapsed_s: float, parts: int) -> float:
    """Seconds each of ``parts`` coarse runs may take when ``elapsed_s`` have gone since the
    command began: :data:`ESTIMATE_S` shared, cut so that the verdict comes within
    :data:`VERDICT_S` (no less than :data:`MIN_ESTIMATE_S`)."""
    left = min(ESTIMATE_S, VERDICT_S - VERDICT_MARGIN_S - elapsed_s)
    return max(left / max(parts, 1), MIN_ESTIMATE_S)


class CoacdLog:
    """What CoACD's ``info`` log tells of a run so far (module doc): rounds, parts searched,
    pieces finished, whether it reached the merge."""

    def __init__(self) -> None:
        self.pools: list[int] = []  # parts waiting at the start of each round
        self.round_done = 0.0  # fraction of the current round searched (its log's percentages)
        self.merging = False
        self.hulls: int | None = None  # the final count, once logged
        # when the search began and reached the merge (read within WATCH_S: the child's
        # start, an interpreter and the imports, is not the search's)
        self.t_search: float | None = None
        self.t_merge: float | None = None

    def feed(self, text: str) -> None:
        for line in text.splitlines():
            if m := _POOL.search(line):
                if not self.pools:
                    self.t_search = time.perf_counter()
                self.pools.append(int(m.group(2)))
                self.round_done = 0.0
            elif m := _PROCESSING.search(line):
                self.round_done = max(self.round_done, float(m.group(1)) / 100.0)
            elif "Merge Convex Hulls" in line:
                self.merging = True
                self.t_merge = time.perf_counter()
            elif m := _HULLS.search(line):
                self.hulls = int(m.group(1))

    @property
    def searched(self) -> float:
        """Parts whose cut was searched: every earlier round's, and the current round's share
        (all of them once the merge began)."""
        if not self.pools:
            return 0.0
        if self.merging:
            return float(sum(self.pools))
        return sum(self.pools[:-1]) + self.round_done * self.pools[-1]

    @property
    def finished(self) -> int:
        """Pieces finished before the merge: each part of a round either is one or is cut in
        two for the next round."""
        done = sum(p - q / 2 for p, q in zip(self.pools, self.pools[1:], strict=False))
        if self.merging and self.pools:
            done += self.pools[-1]
        return round(done)

    @property
    def pieces_at_least(self) -> int:
        """A lower bound on the pieces before the merge: the finished ones and one per part
        still waiting."""
        waiting = 0 if self.merging or not self.pools else self.pools[-1]
        return self.finished + waiting

    @property
    def tree_parts(self) -> int:
        """Parts the search visits in all, once the run reached its merge: 2 x pieces - 1."""
        return int(sum(self.pools))


def coarse_params(params: CoacdParams) -> CoacdParams:
    """``params`` with the tree search capped at :data:`COARSE`."""
    return replace(params, **{k: min(getattr(params, k), v) for k, v in COARSE.items()})


def cost_ratio(params: CoacdParams) -> float:
    """Estimated full / coarse cost per searched part for ``params``: the ratio of their tree
    search iterations, the measured :data:`FULL_OVER_COARSE` at CoACD's defaults carrying
    the rest."""
    c, d = coarse_params(params), CoacdParams()
    at_defaults = d.mcts_iterations / COARSE["mcts_iterations"]
    return FULL_OVER_COARSE * (params.mcts_iterations / c.mcts_iterations) / at_defaults


@dataclass(frozen=True)
class CoacdEstimate:
    """A coarse run's verdict: pieces and seconds of the full run (lower bounds when the
    coarse run did not end in its budget: ``complete`` False)."""

    pieces: int
    seconds: float
    tree_parts: int
    coarse_s: float
    complete: bool

    def text(self) -> str:
        at_least = "" if self.complete else "at least "
        return (
            f"{at_least}{self.pieces} convex pieces and {at_least}{_duration(self.seconds)} "
            f"(a coarse CoACD run of {self.coarse_s:.0f} s)"
        )


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.0f} min"


def estimate(
    mesh, params: CoacdParams, budget_s: float = ESTIMATE_S, run=run_coacd
) -> CoacdEstimate:
    """The full run's pieces and time from a coarse CoACD run of at most ``budget_s``
    (``run``: :func:`~peghole_mjx.geometry.decompose.run_coacd` or a stand-in)."""
    log = CoacdLog()
    t0 = time.perf_counter()

    def stop_at_budget(log: CoacdLog) -> None:
        if time.perf_counter() - t0 > budget_s:
            raise _Budget

    try:
        hulls = run(mesh, coarse_params(params), watch=stop_at_budget, log=log)
    except _Budget:
        hulls = None
    spent = time.perf_counter() - t0
    # the child's start (an interpreter, the imports) is paid once; the search per part
    began = log.t_search if log.t_search is not None else t0 + spent
    start_s = began - t0
    search_s = (log.t_merge if log.t_merge is not None else t0 + spent) - began
    per_part = search_s / max(log.searched, 1.0)
    ratio = cost_ratio(params)
    # every part of every round logged costs a search (a lower bound when stopped)
    parts = max(log.tree_parts, 1)
    complete = hulls is not None
    pieces = len(hulls) if complete else log.pieces_at_least
    if params.max_convex_hull > 0:
        pieces = min(pieces, params.max_convex_hull)
    return CoacdEstimate(pieces, start_s + parts * per_part * ratio, parts, spent, complete)


class _Budget(Exception):
    """The coarse run reached its budget."""


def threshold_error_mm(mesh, threshold: float) -> float:
    """About how far CoACD's hulls may stray from the part at ``threshold``: CoACD measures
    concavity on the mesh scaled into a cube of side 2, so a threshold t allows about t x half
    the part's largest extent (mm)."""
    return threshold * float(max(mesh.extents)) / 2 / MM


def refusal(
    label: str,
    est: CoacdEstimate,
    params: CoacdParams,
    mesh,
    max_hulls: int,
    max_s: float,
    clearance_mm: float | None = None,
) -> str | None:
    """The one-line refusal when ``est`` exceeds the piece cap or ``max_s``, else None; it
    names the estimate and the options that would fit."""
    too_many = est.pieces > max_hulls * COARSE_SLACK
    too_long = est.seconds > max_s
    if not (too_many or too_long):
        return None
    over = []
    if too_many:
        over.append(
            f"more than {COARSE_SLACK:g} x the cap of {max_hulls} pieces (--max-hulls; the "
            "coarse run cuts up to a quarter more)"
        )
    if too_long:
        over.append(f"longer than {_duration(max_s)} (--coacd-max-s)")
    options = []
    if too_many:
        # pieces fall about as 1/threshold (a coarser decomposition cuts less)
        t = min(1.0, params.threshold * est.pieces / max_hulls * 1.5)
        t = max(t, 0.01)  # CoACD's documented range
        err = threshold_error_mm(mesh, t)
        fit = f"--threshold {t:.3g} (hull error about {err:.2g} mm"
        if clearance_mm is not None:
            fit += f" against a {clearance_mm:.3g} mm radial clearance"
        options.append(fit + f") or --max-convex-hull {max_hulls} (CoACD merges to the cap)")
    if too_long:
        options.append(f"--coacd-max-s {math.ceil(est.seconds * 1.5 / 60) * 60}")
    return (
        f"the {label} part needs CoACD: an estimated {est.text()}, {' and '.join(over)}; "
        f"options that would fit: {'; '.join(options)}; or export the part as an extrusion "
        "or a revolution along +z (exact pieces)"
    )


def run_bounded(
    mesh,
    params: CoacdParams,
    est: CoacdEstimate,
    label: str,
    max_s: float = COACD_MAX_S,
    progress: bool = True,
    run=run_coacd,
    max_hulls: int | None = None,
):
    """The full CoACD run with a bar of searched parts out of the estimated total, stopped
    with one line past ``max_s`` or once its pieces exceed ``max_hulls`` x
    :data:`MERGE_SLACK`. Returns the hulls."""
    log = CoacdLog()
    t0 = time.perf_counter()
    total = max(est.tree_parts, 1)
    bar = prog.bar(total, f"CoACD, {label} part (parts searched / estimated)", enabled=progress)

    def watch(log: CoacdLog) -> None:
        nonlocal total
        done = log.searched
        # the log proves at least the parts searched and those waiting: the total grows to it
        proven = int(done) + (0 if log.merging or not log.pools else log.pools[-1])
        if proven > total:
            total = proven
            bar.total = total
        bar.n = min(int(done), total)
        bar.refresh()
        if max_hulls is not None and log.pieces_at_least > max_hulls * MERGE_SLACK:
            raise UserInputError(
                f"CoACD on the {label} part stopped: {log.pieces_at_least} pieces or more, "
                f"more than the cap of {max_hulls} (--max-hulls), against an estimate of "
                f"{est.text()}; raise --threshold, or --max-convex-hull {max_hulls}"
            )
        if time.perf_counter() - t0 > max_s:
            raise UserInputError(
                f"CoACD on the {label} part stopped after {_duration(max_s)} (--coacd-max-s): "
                f"{log.pieces_at_least} pieces or more so far, against an estimate of "
                f"{est.text()}; raise --threshold or --coacd-max-s"
            )

    try:
        hulls = run(mesh, params, watch=watch, log=log)
        bar.n = bar.total
        bar.refresh()
    finally:
        bar.close()
    return hulls


__all__ = [
    "COACD_MAX_S",
    "CoacdEstimate",
    "CoacdLog",
    "estimate",
    "refusal",
    "run_bounded",
]
