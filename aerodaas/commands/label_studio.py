"""``aerodaas label push``, ``pull`` and ``serve``: the Label Studio round trip's options (the work is in
:mod:`aerodaas.commands.label_studio_main`). Exit codes: 0 done; 2 bad input (a folder, an option, a token Label
Studio refuses, an unknown project, Label Studio not answering, labels it returned that cannot be trained on),
named in one line, nothing half-written."""
from __future__ import annotations

import argparse
from pathlib import Path


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


def add_label_studio_parsers(lsub) -> None:
    """Register ``push`` and ``pull`` on the ``label`` command's sub-parsers ``lsub``."""
    p = lsub.add_parser("push", help="make a frames folder (images, classes.txt, tasks.json) a Label Studio project")
    p.add_argument("dir", type=Path, metavar="DIR", help="the folder aerodaas label frames wrote")
    p.add_argument("--project", required=True, metavar="NAME", help="the new project's title (refused if it exists)")
    p.add_argument("--classes", help="class names, comma-separated (default: DIR/classes.txt)")
    _server_options(p)
    p.set_defaults(func=cmd_push)
    q = lsub.add_parser("pull", help="write a Label Studio project's boxes as training sets (reviewed/, machine/)")
    q.add_argument("--project", required=True, metavar="NAME|ID", help="the project's title or id")
    q.add_argument("--out", required=True, type=Path, metavar="TRAINDIR", help="a new folder for the sets")
    q.add_argument("--reviewed-only", action="store_true",
                   help="leave out the frames that kept only the detector's boxes (no reviewer submitted them)")
    _server_options(q)
    q.set_defaults(func=cmd_pull)
    s = lsub.add_parser("serve", help="serve the detector as a Label Studio ML backend (pre-labels on demand)")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; others need "
                                                       "--allow-remote)")
    s.add_argument("--port", type=int, default=9090, help="port (default 9090; 0: any free port, printed)")
    s.add_argument("--allow-remote", action="store_true",
                   help="bind an address other than loopback (the backend has no authentication of its own)")
    s.add_argument("--model", type=Path, help="detector ONNX (default: the shipped aerial_nano)")
    s.add_argument("--score-threshold", type=float, default=0.3, help="lowest score predicted (default 0.3)")
    _server_options(s)
    s.set_defaults(func=cmd_serve)


def cmd_push(args: argparse.Namespace) -> int:
    """``aerodaas label push``: :func:`aerodaas.commands.label_studio_main.cmd_push`."""
    from aerodaas.commands.label_studio_main import cmd_push as run  # lazy: CLI start-up (numpy)

    return run(args)


def cmd_serve(args: argparse.Namespace) -> int:
    """``aerodaas label serve``: :func:`aerodaas.commands.label_studio_main.cmd_serve`."""
    from aerodaas.commands.label_studio_main import cmd_serve as run  # lazy: CLI start-up (onnxruntime, OpenCV)

    return run(args)


def cmd_pull(args: argparse.Namespace) -> int:
    """``aerodaas label pull``: :func:`aerodaas.commands.label_studio_main.cmd_pull`."""
    from aerodaas.commands.label_studio_main import cmd_pull as run  # lazy: CLI start-up (numpy, OpenCV)

    return run(args)
