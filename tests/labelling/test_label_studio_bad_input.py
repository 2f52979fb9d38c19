"""Bad input to ``aerodaas label push`` / ``pull`` and to a Label Studio JSON export given to training, without a
Label Studio server: each ends with one line naming the thing and the value (exit 2), in bounded time, nothing
written; the token is never sent anywhere but the ``--url`` given (no redirect followed, no other origin fetched)."""
from __future__ import annotations

import http.server
import json
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from aerodaas.cli import main
from aerodaas.labelling.label_studio import LabelStudio, LabelStudioError
from aerodaas.training.dataset import load_set
from aerodaas.training.labels.check import LabelError
from tests.labelling.frames_folder import FRAME_NAMES, NAMES, rect, write_frames_folder

TOKEN = "0123456789abcdef0123456789abcdef01234567"


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run(capsys, *args: str) -> tuple[int, str]:
    rc = main(list(args))
    err = capsys.readouterr().err
    return rc, err


class _Recorder(http.server.BaseHTTPRequestHandler):
    """Answers every request with the server's ``reply(handler)`` and records (path, Authorization)."""

    def do_GET(self):  # noqa: N802 - http.server's name
        self.server.seen.append((self.path, self.headers.get("Authorization")))
        self.server.reply(self)

    do_POST = do_GET

    def log_message(self, *a):  # quiet
        pass


@pytest.fixture
def stub():
    """Start loopback HTTP stubs: ``stub(reply)`` returns a server whose ``seen`` lists the requests."""
    servers = []

    def make(reply):
        srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Recorder)
        srv.seen, srv.reply = [], reply
        threading.Thread(target=srv.serve_forever, daemon=True).start()
        servers.append(srv)
        return srv

    yield make
    for s in servers:
        s.shutdown()
        s.server_close()


def test_a_server_that_is_not_there_is_named_at_once(capsys, tmp_path):
    url = f"http://127.0.0.1:{_closed_port()}"
    rc, err = _run(capsys, "label", "pull", "--url", url, "--token", TOKEN, "--project", "x", "--out",
                   str(tmp_path / "out"))
    assert rc == 2 and err.startswith(f"error: url={url!r}: Label Studio does not answer")
    assert TOKEN not in err and not (tmp_path / "out").exists()


def test_a_server_that_never_answers_ends_within_the_timeout(capsys, tmp_path):
    with socket.socket() as s:  # accepts connections (the kernel's backlog) but never answers
        s.bind(("127.0.0.1", 0))
        s.listen(8)
        url = f"http://127.0.0.1:{s.getsockname()[1]}"
        rc, err = _run(capsys, "label", "pull", "--url", url, "--token", TOKEN, "--project", "x", "--timeout", "1",
                       "--out", str(tmp_path / "out"))
    assert rc == 2 and "Label Studio does not answer" in err and "timed out" in err


@pytest.mark.parametrize("url, said", [
    ("http://192.0.2.10:8080", "plain http to a host other than loopback"),
    ("ftp://127.0.0.1", "expected http(s)://HOST[:PORT]"),
    ("http://user:pw@127.0.0.1:8080", "no query, fragment or user"),
])
def test_a_url_that_would_leak_the_token_is_refused_before_any_connection(capsys, tmp_path, url, said):
    rc, err = _run(capsys, "label", "pull", "--url", url, "--token", TOKEN, "--project", "x", "--out",
                   str(tmp_path / "out"))
    assert rc == 2 and said in err and f"--url {url!r}" in err


def test_no_redirect_is_followed_with_the_token(stub):
    """A server answering with a redirect elsewhere: the client refuses it; the other server sees no request."""
    other = stub(lambda h: (h.send_response(200), h.end_headers()))
    port = other.server_address[1]

    def redirect(h):
        h.send_response(302)
        h.send_header("Location", f"http://127.0.0.1:{port}/api/current-user/whoami")
        h.end_headers()

    first = stub(redirect)
    ls = LabelStudio(f"http://127.0.0.1:{first.server_address[1]}", TOKEN, timeout=10)
    with pytest.raises(LabelStudioError, match="redirect to .* refused"):
        ls.whoami()
    assert first.seen == [("/api/current-user/whoami", f"Token {TOKEN}")]
    assert other.seen == []
    with pytest.raises(LabelStudioError, match="is not on the Label Studio server"):
        ls.download(f"http://127.0.0.1:{port}/data/upload/1/x.jpg")
    assert other.seen == []


def test_a_personal_access_token_is_exchanged_for_a_bearer_token(stub):
    """Label Studio 1.23's personal access tokens are JWT refresh tokens (``jwt_auth``): the client trades one at
    ``/api/token/refresh/`` and sends the access token it gets as ``Bearer``."""
    pat = "eyJhbGciOiJIUzI1NiJ9.eyJ0b2tlbl90eXBlIjoicmVmcmVzaCJ9.c2lnbmF0dXJl"

    def reply(h):
        body = (json.dumps({"access": "eyJ.access.tok"}) if h.path == "/api/token/refresh/" else
                json.dumps({"email": "a@b"})).encode()
        h.send_response(200)
        h.send_header("Content-Type", "application/json")
        h.send_header("Content-Length", str(len(body)))
        h.end_headers()
        h.wfile.write(body)

    srv = stub(reply)
    assert LabelStudio(f"http://127.0.0.1:{srv.server_address[1]}", pat, timeout=10).whoami() == {"email": "a@b"}
    assert srv.seen == [("/api/token/refresh/", None), ("/api/current-user/whoami", "Bearer eyJ.access.tok")]


def test_pull_refuses_an_existing_output_folder_before_asking_the_server(capsys, tmp_path):
    (tmp_path / "out").mkdir()
    rc, err = _run(capsys, "label", "pull", "--url", f"http://127.0.0.1:{_closed_port()}", "--token", TOKEN,
                   "--project", "x", "--out", str(tmp_path / "out"))
    assert rc == 2 and "--out" in err and "already exists" in err


@pytest.mark.parametrize("spoil, said", [
    (lambda d, t: (d / "tasks.json").unlink(), "no tasks.json"),
    (lambda d, t: (d / "images" / FRAME_NAMES[1]).unlink(), f"image '{FRAME_NAMES[1]}' is not in"),
    (lambda d, t: t[0]["predictions"][0]["result"][0]["value"].update(rectanglelabels=["boat"]),
     "rectanglelabels=['boat'] is not one of the classes"),
    (lambda d, t: t[2]["predictions"][0]["result"][1]["value"].update(x=99.0, width=3.0),
     "lies outside the 640x512 image"),
])
def test_push_refuses_a_bad_frames_folder_before_contacting_the_server(capsys, tmp_path, spoil, said):
    folder = tmp_path / "frames"
    tasks = write_frames_folder(folder)
    spoil(folder, tasks)
    if (folder / "tasks.json").exists():
        (folder / "tasks.json").write_text(json.dumps(tasks))
    rc, err = _run(capsys, "label", "push", str(folder), "--url", f"http://127.0.0.1:{_closed_port()}",
                   "--token", TOKEN, "--project", "frames")
    assert rc == 2 and said in err and len(err.strip().splitlines()) == 1, err


def _export(tmp_path: Path, tasks: list, names: list[str] | None = NAMES) -> Path:
    folder = tmp_path / "ls_export"
    write_frames_folder(folder)
    (folder / "tasks.json").unlink()  # the export is the folder's one .json
    (folder / "export.json").write_text(json.dumps(tasks))
    if names is None:
        (folder / "classes.txt").unlink()
    return folder


def _task(i: int, annotations: list, predictions: list | None = None) -> dict:
    return {"id": i + 1, "data": {"image": f"/data/local-files/?d=ls_export/images/{FRAME_NAMES[i]}"},
            "annotations": annotations, "predictions": predictions or []}


def test_load_set_reads_a_label_studio_json_export(tmp_path):
    """Reviewed tasks only (a skipped and a machine-only task left out); a rotated box as the box around it."""
    box = rect(100, 50, 140, 70, 640, 512, "car")
    turned = rect(300, 200, 340, 220, 640, 512, "person")
    turned["value"]["rotation"] = 90.0  # clockwise about its top-left corner: (280, 200) to (300, 240)
    tasks = [_task(0, [{"id": 1, "result": [box, turned], "was_cancelled": False}]),
             _task(1, [{"id": 2, "result": [box], "was_cancelled": True}]),
             _task(2, [], [{"id": 3, "result": [box]}]),
             _task(3, [{"id": 4, "result": [], "was_cancelled": False}])]
    items, names = load_set(_export(tmp_path, tasks) / "export.json")
    assert names == NAMES
    assert [it.path.name for it in items] == [FRAME_NAMES[0], FRAME_NAMES[3]]
    np.testing.assert_allclose(items[0].boxes, [[100, 50, 140, 70], [280, 200, 300, 240]], atol=1e-3)
    assert items[0].classes.tolist() == [0, 2] and len(items[1].boxes) == 0


@pytest.mark.parametrize("value, said", [
    ({"rectanglelabels": ["boat"]}, "task 1 annotation 1.result[0]: rectanglelabels=['boat'] is not one of"),
    ({"x": 95.0, "width": 10.0}, "task 1 annotation 1.result[0]: box (608.0, 50.0, 672.0, 70.0) px lies outside"),
])
def test_load_set_names_bad_labels_of_an_export(tmp_path, value, said):
    box = rect(100, 50, 140, 70, 640, 512, "car")
    box["value"].update(value)
    with pytest.raises(LabelError) as e:
        load_set(_export(tmp_path, [_task(0, [{"id": 1, "result": [box]}])]))
    assert any(said in p for p in e.value.problems), e.value.problems


def test_load_set_needs_the_class_names_of_an_export(tmp_path):
    box = rect(100, 50, 140, 70, 640, 512, "car")
    with pytest.raises(LabelError, match="no class list: put classes.txt"):
        load_set(_export(tmp_path, [_task(0, [{"id": 1, "result": [box]}])], names=None))
