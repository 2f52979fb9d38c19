"""Choosing frames to label within a budget: :func:`select_frames` (sources: recordings, videos, image lists) and
:func:`select_images` (image files and their flight ids).

1. **Candidates** (one decode pass): a camera's frames at most ``rate`` per second of its stream (image lists: every
   image), each dropped when its difference hash (:func:`aerodaas.labelling.features.dhash`) is within
   ``dedup_bits`` bits of the previous candidate kept from the same camera (a near-duplicate). Held-out flights are
   never read.
2. **Quotas**: the budget spread over the flights as evenly as their candidates allow (a flight with fewer
   candidates than its share gives the rest to the others; the order in which single leftover frames go is drawn
   from ``seed``), each at most ``per_flight_quota``.
3. **Ranked** (default): per flight, a pool of ``pool_factor`` times its quota is spread over the candidates by
   greedy farthest-point sampling on the appearance embedding (Gonzalez, Theor. Comput. Sci. 38, 1985; start drawn
   from ``seed``); the pool is scored by the detector (:mod:`aerodaas.labelling.scoring`, a second decode pass), and
   the quota picked greedily by ``(1 - w) * informativeness / max + w * distance / max``: the informativeness
   normalised over the pool and the embedding distance to the nearest frame already picked in that flight,
   normalised over the remaining ones (``w``: ``diversity_weight``). **Uniform** (``uniform=True``): the quota evenly
   spaced over the flight's candidates in time order, at a phase drawn from ``seed``; only the picks are scored.

The result is deterministic for a given ``seed`` and input. Bad input raises :class:`LabelInputError` (naming the
value) before any frame is scored: a budget larger than the candidates (saying how many there are), a held-out name
matching no flight, two inputs with one flight name, a source without frames.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np

from aerodaas.labelling.features import dhash, embedding, hamming
from aerodaas.labelling.names import clean_name
from aerodaas.labelling.scoring import Detectors, build_detectors, informativeness, prelabels
from aerodaas.labelling.sources import FrameRef, ImageListSource, LabelInputError
from aerodaas.model.types import Detection

__all__ = ["SelectOptions", "Candidate", "Selection", "select_frames", "select_images", "flight_quotas",
           "Progress"]

#: ``(phase, done, total)``: phase ``"read"`` (candidates; total None) or ``"score"`` (frames scored)
Progress = Callable[[str, int, "int | None"], None]


@dataclass
class SelectOptions:
    """How frames are chosen (module docstring): ``budget`` frames in all (>= 1); ``seed``; ``rate`` candidates
    per second of a stream at most (> 0); ``dedup_bits`` (0-64) of difference hash within which a frame is a
    near-duplicate of the previous candidate; ``per_flight_quota`` (>= 1, None: no cap); ``held_out`` flight
    names (a file stem or its cleaned form) never drawn from; ``uniform`` (evenly spaced instead of ranked);
    ``pool_factor`` (>= 1) and ``diversity_weight`` (0-1) of the ranked pick."""

    budget: int
    seed: int = 0
    rate: float = 1.0
    dedup_bits: int = 6
    per_flight_quota: int | None = None
    held_out: Sequence[str] = ()
    uniform: bool = False
    pool_factor: int = 3
    diversity_weight: float = 0.5

    def check(self) -> None:
        """Raises :class:`LabelInputError` naming the option and the value."""
        if int(self.budget) < 1:
            raise LabelInputError(f"--budget {self.budget}: must be >= 1")
        if not float(self.rate) > 0:
            raise LabelInputError(f"--rate {self.rate}: must be > 0 (candidate frames per second)")
        if not 0 <= int(self.dedup_bits) <= 64:
            raise LabelInputError(f"--dedup-bits {self.dedup_bits}: must be within [0, 64]")
        if self.per_flight_quota is not None and int(self.per_flight_quota) < 1:
            raise LabelInputError(f"--per-flight-quota {self.per_flight_quota}: must be >= 1")
        if int(self.pool_factor) < 1:
            raise LabelInputError(f"--pool-factor {self.pool_factor}: must be >= 1")
        if not 0.0 <= float(self.diversity_weight) <= 1.0:
            raise LabelInputError(f"--diversity-weight {self.diversity_weight}: must be within [0, 1]")


@dataclass
class Candidate:
    """A candidate frame: its :class:`FrameRef`, ``width``/``height`` (pixels), ``hash``
    (:func:`~aerodaas.labelling.features.dhash`), ``embed`` (``(128,)`` float32), and once scored ``scores``
    (:func:`~aerodaas.labelling.scoring.informativeness` plus ``pick_value``/``min_distance`` of the pick) and
    ``boxes`` (the pre-labels, :func:`~aerodaas.labelling.scoring.prelabels`)."""

    ref: FrameRef
    width: int
    height: int
    hash: int
    embed: np.ndarray = field(repr=False)
    scores: dict[str, float] | None = None
    boxes: list[Detection] | None = None
    reason: str = ""


@dataclass
class Selection:
    """What :func:`select_frames` chose: ``picked`` (the frames, by flight then time), ``candidates`` (per flight,
    after sampling and de-duplication), ``read`` (frames decoded per flight in the candidate pass), ``quotas`` (per
    flight), ``options``, ``detectors`` (their settings and model version)."""

    picked: list[Candidate]
    candidates: dict[str, int]
    read: dict[str, int]
    quotas: dict[str, int]
    options: SelectOptions
    detectors: Detectors

    def parameters(self) -> dict:
        """The run's parameters as JSON-able values (options, model version, thresholds, the stronger pass)."""
        d = self.detectors
        return {**asdict(self.options), "held_out": list(self.options.held_out), "model_version": d.model_version,
                "score_threshold": d.score_threshold, "margin": d.margin, "strong": d.strong_kind,
                "classes": list(d.classes)}


def flight_quotas(available: dict[str, int], budget: int, cap: int | None, seed: int) -> dict[str, int]:
    """Frames per flight: ``budget`` spread as evenly as ``available`` (candidates per flight) allows, each at most
    ``cap``; single leftover frames go to flights in an order drawn from ``seed``. Raises :class:`LabelInputError`
    (saying how many are available) when the flights cannot give ``budget`` frames."""
    limit = {f: min(n, cap) if cap else n for f, n in available.items()}
    total = sum(limit.values())
    if total < budget:
        per = ", ".join(f"{f} {n}" for f, n in sorted(available.items()))
        capped = f", at most {cap} per flight (--per-flight-quota)" if cap else ""
        raise LabelInputError(f"--budget {budget}: only {total} candidate frame(s) available{capped} "
                              f"(per flight after sampling and dropping near-duplicates: {per or 'none'})")
    quota = dict.fromkeys(limit, 0)
    order = [sorted(limit)[i] for i in np.random.default_rng(seed).permutation(len(limit))]
    left = budget
    while left > 0:
        open_ = [f for f in order if quota[f] < limit[f]]
        share = left // len(open_)
        if share == 0:
            for f in open_[:left]:
                quota[f] += 1
            break
        for f in open_:
            add = min(share, limit[f] - quota[f])
            quota[f] += add
            left -= add
    return quota


def _farthest_points(embeds: np.ndarray, k: int, rng: np.random.Generator) -> list[int]:
    """``k`` indices of ``embeds`` ``(N, D)`` by greedy farthest-point sampling from a start drawn by ``rng``."""
    n = len(embeds)
    if k >= n:
        return list(range(n))
    first = int(rng.integers(n))
    picked = [first]
    dist = np.linalg.norm(embeds - embeds[first], axis=1)
    for _ in range(k - 1):
        dist[picked] = -1.0
        nxt = int(np.argmax(dist))
        picked.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(embeds - embeds[nxt], axis=1))
    return picked


def _uniform(cands: list[Candidate], q: int, rng: np.random.Generator) -> list[Candidate]:
    """``q`` of ``cands`` (in time order) evenly spaced at a phase drawn from ``rng``."""
    n = len(cands)
    phase = float(rng.uniform(0.0, 1.0))
    idx = sorted({min(n - 1, int((i + phase) * n / q)) for i in range(q)})
    return [cands[i] for i in idx]


def _ranked(pool: list[Candidate], q: int, weight: float, rng: np.random.Generator) -> list[Candidate]:
    """``q`` of the scored ``pool`` picked greedily by informativeness and distance (module docstring)."""
    info = np.array([c.scores["informativeness"] for c in pool], dtype=np.float64)
    info = info / info.max() if info.max() > 0 else np.zeros_like(info)
    info += rng.uniform(0.0, 1e-9, len(pool))  # ties broken by the seed
    emb = np.stack([c.embed for c in pool]).astype(np.float64)
    mind = np.full(len(pool), np.inf)
    chosen: list[int] = []
    for _ in range(min(q, len(pool))):
        free = np.setdiff1d(np.arange(len(pool)), chosen)
        if chosen:
            d = mind[free]
            dn = d / d.max() if d.max() > 0 else np.zeros_like(d)
            value = (1.0 - weight) * info[free] + weight * dn
        else:
            d, value = np.full(len(free), np.nan), info[free]
        j = int(np.argmax(value))
        i = int(free[j])
        pool[i].scores = {**pool[i].scores, "pick_value": float(value[j]),
                          "min_distance": None if np.isnan(d[j]) else float(d[j])}
        pool[i].reason = "most informative" if not chosen else "informative and unlike the frames already picked"
        chosen.append(i)
        mind = np.minimum(mind, np.linalg.norm(emb - emb[i], axis=1))
    return [pool[i] for i in chosen]


def _check_sources(sources: Sequence, held_out: Iterable[str]) -> tuple[list, list[str]]:
    """The sources to read (held-out flights left out) and the held-out flight names; raises
    :class:`LabelInputError` for two inputs of one flight, a held-out name matching none, or a bad source."""
    seen: dict[str, str] = {}
    for s in sources:
        if s.flight in seen:
            raise LabelInputError(f"inputs {seen[s.flight]!r} and {s.source!r} have the same flight name "
                                  f"{s.flight!r}: rename one")
        seen[s.flight] = s.source
    held = []
    for h in held_out:
        name = clean_name(str(h), "")
        if name not in seen:
            raise LabelInputError(f"--held-out {h!r}: matches no input flight (flights: {sorted(seen)})")
        held.append(name)
    use = [s for s in sources if s.flight not in held]
    if not use:
        raise LabelInputError(f"--held-out {list(held_out)}: every input flight is held out")
    for s in use:
        s.check()
    return use, held


def _candidates(sources: Sequence, opts: SelectOptions, progress: Progress | None
                ) -> tuple[dict[str, list[Candidate]], dict[str, int]]:
    """Pass 1: the candidates of each flight (sampled at ``opts.rate``, near-duplicates dropped) and the frames
    decoded per flight."""
    out: dict[str, list[Candidate]] = {}
    read: dict[str, int] = {}
    done = 0
    for s in sources:
        last_t: dict[str, float] = {}
        last_hash: dict[str, int] = {}
        flight = out.setdefault(s.flight, [])
        read[s.flight] = 0

        def want(ref: FrameRef) -> bool:
            if ref.t_s is None:
                return True
            prev = last_t.get(ref.camera)
            if prev is not None and ref.t_s < prev + 1.0 / opts.rate - 1e-6:
                return False
            last_t[ref.camera] = ref.t_s
            return True

        for ref, img in s.frames(want):
            read[s.flight] += 1
            done += 1
            h = dhash(img)
            prev_h = last_hash.get(ref.camera)
            if prev_h is None or hamming(h, prev_h) > opts.dedup_bits:
                last_hash[ref.camera] = h
                flight.append(Candidate(ref, img.shape[1], img.shape[0], h, embedding(img)))
            if progress is not None:
                progress("read", done, None)
    return out, read


def _score(sources: Sequence, pool: dict[tuple, Candidate], dets: Detectors, progress: Progress | None) -> None:
    """Pass 2: both detector passes on every frame of ``pool`` (by :attr:`FrameRef.key`); fills ``scores`` and
    ``boxes``."""
    done = 0
    for s in sources:
        for ref, img in s.frames(lambda r: r.key in pool):
            c = pool[ref.key]
            base, strong = dets.detect(img)
            c.scores = informativeness(base, strong, dets.score_threshold, dets.margin)
            c.boxes = prelabels(base, strong, dets.score_threshold)
            done += 1
            if progress is not None:
                progress("score", done, len(pool))


def select_frames(sources: Sequence, options: SelectOptions, detectors: Detectors | None = None,
                  progress: Progress | None = None) -> Selection:
    """Choose ``options.budget`` frames of ``sources`` (:class:`~aerodaas.labelling.sources.McapSource`,
    :class:`~aerodaas.labelling.sources.VideoSource`, :class:`~aerodaas.labelling.sources.ImageListSource` or
    any object with ``flight``, ``source``, ``check()`` and ``frames(want)``) as the module docstring says.
    ``detectors``: default :func:`~aerodaas.labelling.scoring.build_detectors` ``()`` (the shipped aerial model);
    ``progress``: called as ``(phase, done, total)``. Nothing is written. Raises :class:`LabelInputError` for bad
    input, naming it."""
    options.check()
    use, _held = _check_sources(list(sources), options.held_out)
    per, read = _candidates(use, options, progress)
    quotas = flight_quotas({f: len(c) for f, c in per.items()}, int(options.budget), options.per_flight_quota,
                           int(options.seed))
    dets = detectors if detectors is not None else build_detectors()
    rng = np.random.default_rng(int(options.seed))
    chosen: dict[str, list[Candidate]] = {}
    for flight in sorted(per):
        cands, q = per[flight], quotas[flight]
        if q == 0:
            chosen[flight] = []
        elif options.uniform:
            chosen[flight] = _uniform(cands, q, rng)
        else:
            k = min(len(cands), q * int(options.pool_factor))
            chosen[flight] = [cands[i] for i in sorted(_farthest_points(np.stack([c.embed for c in cands]), k, rng))]
    _score(use, {c.ref.key: c for cs in chosen.values() for c in cs}, dets, progress)
    picked = []
    for flight in sorted(chosen):
        got = chosen[flight]
        if options.uniform:
            for c in got:
                c.reason = "evenly spaced (uniform)"
        else:
            got = _ranked(got, quotas[flight], float(options.diversity_weight), rng)
        picked += sorted(got, key=lambda c: (c.ref.camera, c.ref.index))
    return Selection(picked, {f: len(c) for f, c in per.items()}, read, quotas, options, dets)


def select_images(paths: Sequence[str], flights: Sequence[str], options: SelectOptions,
                  detectors: Detectors | None = None, progress: Progress | None = None) -> Selection:
    """:func:`select_frames` over image files: ``paths[i]`` belongs to flight ``flights[i]`` (frames of one flight
    in the order given; the rate limit does not apply to images, the near-duplicate check does). Each pick's
    ``ref.source`` is its image path. Raises :class:`LabelInputError` when the two lists differ in length, plus
    what :func:`select_frames` raises."""
    if len(paths) != len(flights):
        raise LabelInputError(f"paths ({len(paths)}) and flights ({len(flights)}) must have the same length")
    groups: dict[str, list[str]] = {}
    for p, f in zip(paths, flights):
        groups.setdefault(str(f), []).append(str(p))
    sources = [ImageListSource(ps, f) for f, ps in groups.items()]
    return select_frames(sources, options, detectors, progress)
