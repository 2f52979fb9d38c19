"""``aerodaas label ...``: turn your own footage into labelled frames. ``label frames`` picks the frames worth
labelling out of recordings (``aerodaas run --record``) and videos within a budget and writes them with the shipped
detector's boxes as pre-labels (Label Studio tasks, CVAT XML, COCO JSON; docs/training.md, "Frames worth
labelling"). ``push``, ``pull`` and ``serve`` carry the frames and pre-labels to a Label Studio project and the
reviewed boxes back as training sets. Handlers: :func:`run_frames`, :func:`run_push`, :func:`run_pull`,
:func:`run_serve`; the work is in :mod:`aerodaas.labelling`, imported when a handler runs. Exit codes: 0 written;
2 bad input (files, options, classes, a token Label Studio refuses, an unknown project, Label Studio not
answering, labels it returned that cannot be trained on), named in one line before anything is written; 1 the run
failed (nothing is left half-written).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

#: what each phase of ``label frames`` is called on the progress bar
_PHASES = {"read": "reading frames", "score": "scoring", "write": "writing"}


def add_parser(sub) -> None:
    """Register the ``label`` group and its sub-commands ``frames``, ``push``, ``pull`` and ``serve`` on the CLI's
    sub-parsers ``sub``; more sub-commands go on the ``what`` sub-parsers the same way."""
    lp = sub.add_parser("label", help="label your own footage: pick frames, Label Studio push, pull and serve")
    what = lp.add_subparsers(dest="what", required=True)
    _add_frames(what)
    _add_label_studio(what)


def _add_frames(what) -> None:
    f = what.add_parser("frames", help="frames worth labelling out of recordings and videos, with pre-labels")
    f.add_argument("inputs", nargs="+", type=Path, metavar="RUN.mcap|VIDEO",
                   help="MCAP recordings (aerodaas run --record) and video files; each file is one flight, "
                        "named by its stem")
    f.add_argument("--budget", type=int, required=True, help="frames to pick in all")
    f.add_argument("--out", type=Path, required=True, help="output folder (new or empty)")
    f.add_argument("--held-out", action="append", default=[], metavar="FLIGHT",
                   help="a flight (file stem) never drawn from, kept for evaluation (repeatable)")
    f.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    f.add_argument("--classes", help="classes to pre-label, comma-separated (default: all of the model's)")
    f.add_argument("--model", default="aerial_nano", help="detector name or YOLOX .onnx path (default aerial_nano)")
    f.add_argument("--per-flight-quota", type=int, metavar="Q", help="at most Q frames from one flight")
    f.add_argument("--uniform", action="store_true",
                   help="evenly spaced frames (same budget and quotas) instead of the ranked choice")
    f.add_argument("--rate", type=float, default=1.0, help="candidate frames per second of footage, at most (1)")
    f.add_argument("--dedup-bits", type=int, default=6,
                   help="a frame within this many bits of difference hash of the previous candidate is a "
                        "near-duplicate (0-64, default 6)")
    f.add_argument("--score", type=float, default=0.3, help="detector score threshold of the pre-labels (0.3)")
    f.add_argument("--margin", type=float, default=0.15,
                   help="detections within this of --score count as uncertain (0.15)")
    f.add_argument("--strong", choices=("enlarged", "tiles"), default="enlarged",
                   help="the stronger pass: the model at 1.5x its input, or 640 px tiles (default enlarged)")
    f.add_argument("--pool-factor", type=int, default=3,
                   help="frames scored per frame picked, spread by appearance (default 3)")
    f.add_argument("--diversity-weight", type=float, default=0.5,
                   help="weight of appearance diversity against informativeness, 0-1 (0.5)")
    f.add_argument("--document-root", type=Path,
                   help="Label Studio's LOCAL_FILES_DOCUMENT_ROOT the task image URLs are relative to "
                        "(default: the parent of --out)")
    f.add_argument("--threads", type=int, default=1, help="onnxruntime threads (default 1)")
    f.set_defaults(func=run_frames)


def _server_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--url", default="http://127.0.0.1:8080",
                   help="the Label Studio server (default http://127.0.0.1:8080); the token goes there only")
    tok = p.add_mutually_exclusive_group()
    tok.add_argument("--token-file", type=Path, metavar="F",
                     help="a file holding your Label Studio API token (Account & Settings; preferred: not shown in "
                          "the process list)")
    tok.add_argument("--token", metavar="T", help="the token itself (default: the environment's LABEL_STUDIO_API_KEY)")
    p.add_argument("--insecure-http", action="store_true",
                   help="allow plain http to a host other than loopback (the token travels unencrypted)")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds Label Studio may take to answer (default 60)")
    p.add_argument("--document-root", type=Path, metavar="R",
                   help="Label Studio's LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT (default: that environment variable; "
                        "push: else DIR's parent)")


def _add_label_studio(lsub) -> None:
    """Register ``push``, ``pull`` and ``serve`` on the ``label`` command's sub-parsers ``lsub``."""
    p = lsub.add_parser("push", help="make a frames folder (images, classes.txt, tasks.json) a Label Studio project")
    p.add_argument("dir", type=Path, metavar="DIR", help="the folder aerodaas label frames wrote")
    p.add_argument("--project", required=True, metavar="NAME", help="the new project's title (refused if it exists)")
    p.add_argument("--classes", help="class names, comma-separated (default: DIR/classes.txt)")
    _server_options(p)
    p.set_defaults(func=run_push)
    q = lsub.add_parser("pull", help="write a Label Studio project's boxes as training sets (reviewed/, machine/)")
    q.add_argument("--project", required=True, metavar="NAME|ID", help="the project's title or id")
    q.add_argument("--out", required=True, type=Path, metavar="TRAINDIR", help="a new folder for the sets")
    q.add_argument("--reviewed-only", action="store_true",
                   help="leave out the frames that kept only the detector's boxes (no reviewer submitted them)")
    _server_options(q)
    q.set_defaults(func=run_pull)
    s = lsub.add_parser("serve", help="serve the detector as a Label Studio ML backend (pre-labels on demand)")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; others need "
                                                       "--allow-remote)")
    s.add_argument("--port", type=int, default=9090, help="port (default 9090; 0: any free port, printed)")
    s.add_argument("--allow-remote", action="store_true",
                   help="bind an address other than loopback (the backend has no authentication of its own)")
    s.add_argument("--model", type=Path, help="detector ONNX (default: the shipped aerial_nano)")
    s.add_argument("--score-threshold", type=float, default=0.3, help="lowest score predicted (default 0.3)")
    _server_options(s)
    s.set_defaults(func=run_serve)


def run_frames(args: argparse.Namespace) -> int:
    """``aerodaas label frames``: select and write the frames with their pre-labels
    (:func:`aerodaas.labelling.frames.label_frames`) under a progress bar; print where the frames are and how many
    per flight. Exit 0; 2 bad input, named before anything is written; 1 the run failed (the output folder is then
    absent)."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,  # lazy: CLI start-up (rich)
                               TimeElapsedColumn)

    from aerodaas.labelling.frames import label_frames  # lazy: CLI start-up (cv2, av, onnxruntime)
    from aerodaas.labelling.select import SelectOptions  # lazy: CLI start-up (numpy)
    from aerodaas.labelling.sources import LabelInputError  # lazy: CLI start-up (cv2, av, mcap)

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


def _client(args: argparse.Namespace):
    """The :class:`~aerodaas.labelling.label_studio.LabelStudio` client of ``--url``, the token and ``--timeout``.
    Raises LabelStudioError naming a bad option."""
    from aerodaas.labelling.label_studio import (LabelStudio, LabelStudioError,  # lazy: CLI start-up (labelling)
                                                 read_token)

    if not args.timeout > 0:
        raise LabelStudioError(f"--timeout={args.timeout}: must be > 0 seconds")
    return LabelStudio(args.url, read_token(args.token_file, args.token), timeout=args.timeout,
                       insecure_http=args.insecure_http)


def run_push(args: argparse.Namespace) -> int:
    """``aerodaas label push``: the frames folder as a new Label Studio project
    (:func:`aerodaas.labelling.push.push`); print the project's address. Exit 0, or 2 naming the problem."""
    from aerodaas.labelling.label_studio import LabelStudioError  # lazy: CLI start-up (the labelling package)
    from aerodaas.labelling.push import push  # lazy: CLI start-up (numpy)

    classes = [c.strip() for c in args.classes.split(",") if c.strip()] if args.classes else None
    try:
        r = push(_client(args), args.dir, args.project, classes=classes, root=args.document_root)
    except LabelStudioError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"project {args.project!r} (id {r.project_id}): {r.tasks} tasks, {r.predictions} with pre-labels")
    print(r.url)
    return 0


def run_pull(args: argparse.Namespace) -> int:
    """``aerodaas label pull``: the project's boxes as training sets (:func:`aerodaas.labelling.pull.pull`); print
    what was written and the train command. Exit 0, or 2 naming the problem."""
    from aerodaas.labelling.label_studio import LabelStudioError  # lazy: CLI start-up (the labelling package)
    from aerodaas.labelling.pull import pull  # lazy: CLI start-up (numpy, OpenCV)

    try:
        root = args.document_root or os.environ.get("LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT") or None
        r = pull(_client(args), args.project, args.out, reviewed_only=args.reviewed_only, root=root)
    except LabelStudioError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"{r.out}: {r.reviewed} reviewed frame(s) in reviewed/, {r.machine} machine-labelled in machine/, "
          f"{r.skipped} left out; classes {r.names}")
    sets = [f"--data {r.out / s}" for s, n in (("reviewed", r.reviewed), ("machine", r.machine)) if n]
    print(f"train: aerodaas train detector {' '.join(sets)} --names {','.join(r.names)}")
    return 0


def _backend(args: argparse.Namespace):
    """The :class:`~aerodaas.labelling.ml_backend.DetectorBackend` of ``serve``'s options. Raises LabelStudioError
    naming a bad option."""
    from aerodaas.clusters.tls import is_loopback  # lazy: CLI start-up (the cluster package)
    from aerodaas.labelling.label_studio import LabelStudioError  # lazy: CLI start-up (the labelling package)
    from aerodaas.labelling.ml_backend import DetectorBackend, load_detector  # lazy: OpenCV

    if not is_loopback(args.host) and not args.allow_remote:
        raise LabelStudioError(f"--host {args.host!r}: not loopback; the backend has no authentication of its own "
                               f"(give --allow-remote on a network you trust)")
    if not 0.0 <= args.score_threshold <= 1.0:
        raise LabelStudioError(f"--score-threshold={args.score_threshold}: must be in [0, 1]")
    det, version = load_detector(args.model, args.score_threshold)
    has_token = args.token_file is not None or args.token or os.environ.get("LABEL_STUDIO_API_KEY")
    studio = _client(args) if has_token else None
    root = args.document_root or os.environ.get("LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT")
    return DetectorBackend(det, version, Path(root) if root else None, studio)


def run_serve(args: argparse.Namespace) -> int:
    """``aerodaas label serve``: the detector as a Label Studio ML backend
    (:func:`aerodaas.labelling.ml_backend.make_server`) until interrupted; print the address to give Label Studio.
    Exit 0 on Ctrl-C, 2 for bad options or an address that cannot be bound."""
    from aerodaas.labelling.label_studio import LabelStudioError  # lazy: CLI start-up (the labelling package)
    from aerodaas.labelling.ml_backend import make_server  # lazy: OpenCV

    try:
        backend = _backend(args)
        srv = make_server(backend, args.host, args.port)
    except (LabelStudioError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    host, port = srv.server_address[:2]
    print(f"ML backend {backend.model_version} at http://{host}:{port} (Label Studio: Settings > Model > Connect "
          f"Model)", flush=True)
    try:
        srv.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        srv.server_close()
    return 0
