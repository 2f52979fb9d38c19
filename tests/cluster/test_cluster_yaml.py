"""The commands of clusters/edge-cloud-*.yaml, run in bash as `ray up` runs them (Ray's own login-shell wrapper and
environment prefixes), with stand-ins for python3 / pip / ray that record what they were asked to do: init commands
edit ~/.bashrc once however often they run, the venv is created once, the install reads only the wheelhouse when
there is one and runs again only when pyproject.toml or the wheelhouse changed, and `ray start` gets the node's
address, its tier label, token auth and (on-prem) autoscaler v1. Ray's schema validation of both files is in
tests/cluster/test_edgecloud_cluster.py; the real `ray up` in tests/cluster/test_ray_up.py."""
from __future__ import annotations

import os
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from aerodaas.clusters.log_monitor import SETTINGS as LOG_MONITOR_SETTINGS

REPO = Path(__file__).resolve().parents[2]
FILES = ["edge-cloud-onprem.yaml", "edge-cloud-aws.yaml"]
pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")

# Records its argv (one line per call) in $CALLS; as python3 -m venv DIR it makes DIR/bin/python (this stand-in).
STANDIN = """#!/bin/sh
echo "$(basename "$0") $*" >> "$CALLS"
if [ "$1" = "-m" ] && [ "$2" = "venv" ]; then mkdir -p "$3/bin" && cp "$0" "$3/bin/python"; fi
if [ "$(basename "$0")" = ray ]; then echo "env RAY_AUTH_MODE=$RAY_AUTH_MODE v2=$RAY_enable_autoscaler_v2 RAY_LOG_MONITOR_MANY_FILES_THRESHOLD=$RAY_LOG_MONITOR_MANY_FILES_THRESHOLD" >> "$CALLS"; fi
exit 0
"""


def _cfg(name: str) -> dict:
    return yaml.safe_load((REPO / "clusters" / name).read_text())


@pytest.fixture
def node(tmp_path):
    """A node's home with Debian's default ~/.bashrc, stand-ins first on PATH, and a run(cmds, env) helper that
    runs commands like Ray's SSH command runner (`bash --login -c -i 'source ~/.bashrc; ... && (cmd)'`)."""
    home = tmp_path / "home"
    (home / "aerodaas").mkdir(parents=True)
    (home / "aerodaas" / "pyproject.toml").write_text("[project]\nname = 'aerodaas'\n")
    skel = Path("/etc/skel/.bashrc")
    (home / ".bashrc").write_text(skel.read_text() if skel.is_file() else "case $- in *i*) ;; *) return;; esac\n")
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    for tool in ("python3", "ray"):
        (bin_ / tool).write_text(STANDIN)
        (bin_ / tool).chmod(0o755)
    calls = tmp_path / "calls.txt"
    calls.touch()

    def run(cmds: list[str], **env: str) -> str:
        before = calls.read_text()
        base = {"HOME": str(home), "PATH": f"{bin_}:/usr/bin:/bin", "CALLS": str(calls), "TERM": "dumb"}
        for cmd in cmds:
            inner = f"source ~/.bashrc; export OMP_NUM_THREADS=1 PYTHONWARNINGS=ignore && ({cmd})"
            p = subprocess.run(["bash", "--norc", "--noprofile", "-c", "-i", inner], cwd=home, env={**base, **env},
                               capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)
            assert p.returncode == 0, (cmd, p.stdout, p.stderr)
        return calls.read_text()[len(before):]

    run.home = home
    return run


@pytest.mark.parametrize("name", FILES)
def test_init_commands_edit_bashrc_once(name, node):
    cfg = _cfg(name)
    for _ in range(3):  # three `ray up`s
        node(cfg["initialization_commands"])
    bashrc = (node.home / ".bashrc").read_text()
    assert bashrc.count(". ~/.aerodaas-env") == 1 and "RAY_AUTH_MODE" not in bashrc
    env = (node.home / ".aerodaas-env").read_text()
    assert "export RAY_AUTH_MODE=token" in env and "aerodaas-venv/bin" in env
    out = subprocess.run(["bash", "-c", "cd ~ && . ~/.aerodaas-env && pwd && echo $RAY_AUTH_MODE && echo $PATH"],
                         env={"HOME": str(node.home), "PATH": "/usr/bin:/bin"}, capture_output=True, text=True)
    pwd, mode, path = out.stdout.split()
    assert pwd == str(node.home / "aerodaas") and mode == "token"  # `ray attach` lands in the checkout
    assert path.split(":")[0] == str(node.home / "aerodaas-venv" / "bin")


@pytest.mark.parametrize("name", FILES)
def test_setup_commands_install_once_and_offline_from_the_wheelhouse(name, node):
    cfg = _cfg(name)
    node(cfg["initialization_commands"])
    setup = cfg["setup_commands"]
    first = node(setup)
    assert first.count("python3 -m venv") == 1
    install = [c for c in first.splitlines() if " pip install " in f" {c} "]
    assert len(install) == 1 and "--no-index" not in install[0] and install[0].endswith("-e .")  # PyPI: no wheelhouse
    assert node(setup) == ""  # again: venv kept, nothing installed
    (node.home / "aerodaas" / "wheelhouse").mkdir()
    (node.home / "aerodaas" / "wheelhouse" / "ray-2.60.0-cp311-cp311-manylinux2014_x86_64.whl").write_bytes(b"")
    third = node(setup)
    assert "python3 -m venv" not in third
    (line,) = [c for c in third.splitlines() if "pip install" in c]
    assert f"--no-index --find-links {node.home}/aerodaas/wheelhouse" in line  # offline: only the wheelhouse
    assert node(setup) == ""
    (node.home / "aerodaas" / "pyproject.toml").write_text("[project]\nname = 'aerodaas'\nversion = '0.2'\n")
    assert "pip install" in node(setup)


@pytest.mark.parametrize("name", FILES)
def test_ray_start_gets_the_ssh_address_label_and_token_mode(name, node):
    from ray.autoscaler._private.util import with_envs

    cfg = _cfg(name)
    node(cfg["initialization_commands"])
    for kind, tier, ip in (("head", "edge", "10.213.0.1"), ("worker", "cloud", "10.213.0.2")):
        cmds = cfg[f"{kind}_start_ray_commands"]
        if kind == "head":  # what `ray up` (autoscaler v2 default since Ray 2.50) prefixes to the head's commands
            cmds = with_envs(cmds, {"RAY_enable_autoscaler_v2": "1", "RAY_CLOUD_INSTANCE_ID": ip,
                                    "RAY_NODE_TYPE_NAME": "t"})
        else:  # what the head's autoscaler prefixes (commands.py / autoscaler.py with_head_node_ip)
            cmds = with_envs(cmds, {"RAY_HEAD_IP": "10.213.0.1"})
        # sshd sets SSH_CONNECTION="client_ip client_port server_ip server_port"; the node's address is the 3rd
        calls = node(cmds, SSH_CONNECTION=f"10.213.0.9 50022 {ip} 22").splitlines()
        starts = [c for c in calls if c.startswith("ray start")]
        assert calls[0].split() == ["ray", "stop"] and len(starts) == 1, calls  # the node stops its own Ray first
        args = shlex.split(starts[0])
        assert f"--node-ip-address={ip}" in args and args[args.index("--labels") + 1] == f"tier={tier}"
        if kind == "worker":
            assert "--address=10.213.0.1:6379" in args
        else:  # the dashboard (HTTP) stays on the head's loopback; `ray dashboard` tunnels to it over SSH
            assert "--dashboard-host=127.0.0.1" in args, args
        env = calls[calls.index(starts[0]) + 1]
        assert "RAY_AUTH_MODE=token" in env
        # the log monitor's settings of every node AeroDaaS starts itself (aerodaas.clusters.log_monitor)
        assert all(f"{k}={v}" in env.split() for k, v in LOG_MONITOR_SETTINGS.items()), env
        if kind == "head" and cfg["provider"]["type"] == "local":
            assert "v2=0" in env  # on-prem: autoscaler v1 whatever `ray up` exports (the YAML's comment says why)


def test_onprem_file_only_needs_addresses_user_and_key():
    """The smoke test edits exactly these fields of a copy; everything else is as shipped."""
    script = (REPO / "clusters" / "smoke" / "ray_up_test.sh").read_text()
    edits = [line.strip() for line in script.splitlines() if line.strip().startswith('cfg["')]
    assert sorted(e.split("=")[0].strip() for e in edits) == ['cfg["auth"]', 'cfg["provider"]["head_ip"]',
                                                              'cfg["provider"]["worker_ips"]']
    assert 'cfg["auth"] = {"ssh_user"' in script and "ssh_private_key" in script
    assert os.access(REPO / "clusters" / "smoke" / "ray_up_test.sh", os.X_OK)
