"""``aerodaas label push`` / ``pull`` themselves (options: :mod:`aerodaas.commands.label_studio`): the token read,
the Label Studio client made, the round trip run; any bad input ends with exit 2 and one line naming it."""
from __future__ import annotations

import argparse
import hashlib
import os
import sys
from pathlib import Path

from aerodaas.clusters.tls import is_loopback
from aerodaas.labelling.label_studio import LabelStudio, LabelStudioError
from aerodaas.labelling.pull import pull
from aerodaas.labelling.push import push

#: the largest token file read (bytes)
_MAX_TOKEN_BYTES = 16384


def _token(args: argparse.Namespace) -> str:
    if args.token_file is not None:
        try:
            with open(args.token_file, "rb") as f:
                raw = f.read(_MAX_TOKEN_BYTES + 1)
        except OSError as e:
            raise LabelStudioError(f"--token-file {str(args.token_file)!r}: cannot be read ({e.strerror})") from None
        if len(raw) > _MAX_TOKEN_BYTES:
            raise LabelStudioError(f"--token-file {str(args.token_file)!r}: larger than {_MAX_TOKEN_BYTES} bytes, "
                                   f"not a token")
        return raw.decode("utf-8", "replace").strip()
    token = args.token or os.environ.get("LABEL_STUDIO_API_KEY", "")
    if not token:
        raise LabelStudioError("token: give --token-file F (or --token T, or LABEL_STUDIO_API_KEY)")
    return token


def _client(args: argparse.Namespace) -> LabelStudio:
    if not args.timeout > 0:
        raise LabelStudioError(f"--timeout={args.timeout}: must be > 0 seconds")
    return LabelStudio(args.url, _token(args), timeout=args.timeout, insecure_http=args.insecure_http)


def cmd_push(args: argparse.Namespace) -> int:
    """Push the frames folder; print the project's address. Exit 0, or 2 naming the problem."""
    classes = [c.strip() for c in args.classes.split(",") if c.strip()] if args.classes else None
    try:
        r = push(_client(args), args.dir, args.project, classes=classes, root=args.document_root)
    except LabelStudioError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"project {args.project!r} (id {r.project_id}): {r.tasks} tasks, {r.predictions} with pre-labels")
    print(r.url)
    return 0


def cmd_pull(args: argparse.Namespace) -> int:
    """Pull the project into training sets; print what was written and the train command. Exit 0, or 2."""
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
    """The detector backend of ``serve`` (imports onnxruntime and OpenCV)."""
    from aerodaas.labelling.ml_backend import DetectorBackend  # lazy: OpenCV
    from aerodaas.perception.detect import AerialDetector  # lazy: onnxruntime

    if not is_loopback(args.host) and not args.allow_remote:
        raise LabelStudioError(f"--host {args.host!r}: not loopback; the backend has no authentication of its own "
                               f"(give --allow-remote on a network you trust)")
    if not 0.0 <= args.score_threshold <= 1.0:
        raise LabelStudioError(f"--score-threshold={args.score_threshold}: must be in [0, 1]")
    try:
        det = AerialDetector(args.model, score_threshold=args.score_threshold)
    except (OSError, ValueError) as e:
        raise LabelStudioError(f"--model {str(args.model)!r}: {e}") from None
    path = Path(det.model_path)
    version = f"{path.stem}@{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}"
    has_token = args.token_file is not None or args.token or os.environ.get("LABEL_STUDIO_API_KEY")
    studio = _client(args) if has_token else None
    root = args.document_root or os.environ.get("LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT")
    return DetectorBackend(det, version, Path(root) if root else None, studio)


def cmd_serve(args: argparse.Namespace) -> int:
    """Serve the detector to Label Studio until interrupted; print the address to give Label Studio. Exit 0 on
    Ctrl-C, 2 for bad options or an address that cannot be bound."""
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
