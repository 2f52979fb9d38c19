"""``aerodaas label frames`` itself (its options: :mod:`aerodaas.commands.label`): the options checked, the frames
selected and written by :func:`aerodaas.labelling.frames.label_frames` under a progress bar. Exit codes: 0 written;
2 bad input, named before anything is written; 1 the run failed (the output folder is then absent).
"""
from __future__ import annotations

import argparse
import sys

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from aerodaas.labelling.frames import label_frames
from aerodaas.labelling.select import SelectOptions
from aerodaas.labelling.sources import LabelInputError

#: what each phase of the run is called on the progress bar
_PHASES = {"read": "reading frames", "score": "scoring", "write": "writing"}


def cmd_label_frames(args: argparse.Namespace) -> int:
    """Select and write (module docstring); print where the frames are and how many per flight."""
    classes = [c.strip() for c in args.classes.split(",") if c.strip()] if args.classes else None
    if args.classes is not None and not classes:
        print(f"error: --classes {args.classes!r}: names no class", file=sys.stderr)
        return 2
    opts = SelectOptions(budget=args.budget, seed=args.seed, rate=args.rate, dedup_bits=args.dedup_bits,
                         per_flight_quota=args.per_flight_quota, held_out=list(args.held_out), uniform=args.uniform,
                         pool_factor=args.pool_factor, diversity_weight=args.diversity_weight)
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  transient=True) as bar:
        tasks: dict[str, int] = {}

        def progress(phase: str, done: int, total: int | None) -> None:
            if phase not in tasks:
                tasks[phase] = bar.add_task(_PHASES.get(phase, phase), total=total)
            bar.update(tasks[phase], completed=done, total=total)

        try:
            sel = label_frames(args.inputs, args.out, opts, model=args.model, classes=classes,
                               score_threshold=args.score, margin=args.margin, strong=args.strong,
                               document_root=args.document_root, threads=args.threads, progress=progress)
        except LabelInputError as e:
            bar.stop()
            print(f"error: {e}", file=sys.stderr)
            return 2
        except (OSError, RuntimeError, ValueError) as e:
            bar.stop()
            print(f"error: label frames failed ({type(e).__name__}: {e}); nothing was written to {args.out}",
                  file=sys.stderr)
            return 1
    per = ", ".join(f"{f} {n}/{sel.candidates[f]}" for f, n in sorted(sel.quotas.items()))
    print(f"{len(sel.picked)} frames ({'uniform' if opts.uniform else 'ranked'}) with pre-labels in {args.out} "
          f"(picked/candidates per flight: {per}); model {sel.detectors.model_version}")
    return 0
