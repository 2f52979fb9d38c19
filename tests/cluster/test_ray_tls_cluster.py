"""Ray's own TLS on a multi-node cluster: a two-node ``LocalCluster`` runs Ray's mutual TLS
(``RAY_USE_TLS`` and the ``RAY_TLS_*`` files of a private certificate authority, set for every Ray process,
``aerodaas run --address``'s driver included); a mission flies on it; the GCS and both raylets answer only a TLS
client holding a certificate of that authority, and a driver without the certificates, or with one of another
authority, cannot join the cluster although it holds the cluster's token. The negative drivers are bounded by
Ray's own GCS connect time-outs (shortened here) and by the subprocess time-out."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO

SCRIPT = textwrap.dedent(r'''
    import json, os, subprocess, sys
    from aerodaas.clusters.addresses import check_ray_address
    from aerodaas.clusters.local import LocalCluster
    from aerodaas.clusters.ray_tls import TLS_VARIABLES, RayTLS

    ca, crt, key, other_ca, other_crt, other_key, app, rec = sys.argv[1:9]
    CLIENT = ("import ray, sys; ray.init(address=sys.argv[1], logging_level='error'); "
              "print('CONNECTED', sorted(n['NodeManagerPort'] for n in ray.nodes() if n['Alive']))")
    # Ray's time-outs for a driver that cannot reach the GCS (defaults: 5 s per connect, 60 s to give up)
    QUICK = {"RAY_gcs_rpc_server_connect_timeout_s": "2", "RAY_gcs_rpc_server_reconnect_timeout_s": "3",
             "RAY_gcs_server_port_wait_time_s": "2"}

    def answers(address, with_tls):
        """check_ray_address with or without Ray's TLS variables in this process: '' or why it refused."""
        saved = {v: os.environ.pop(v) for v in TLS_VARIABLES if not with_tls and v in os.environ}
        try:
            check_ray_address(address, timeout_s=10.0)
            return ""
        except ValueError as e:
            return str(e)
        finally:
            os.environ.update(saved)

    out = {}
    with LocalCluster(cloud_nodes=1, connect=False, tls=RayTLS.checked(crt, key, ca)) as lc:
        out["env"] = {v: os.environ.get(v) for v in TLS_VARIABLES}
        ports = {"gcs": lc.address} | {f"raylet{i}": f"127.0.0.1:{n.node_manager_port}"
                                       for i, n in enumerate([lc.edge_node] + lc.cloud_nodes)}
        out["raylet_ports"] = sorted(n.node_manager_port for n in [lc.edge_node] + lc.cloud_nodes)
        out["tls_check"] = {k: answers(a, True) for k, a in ports.items()}
        out["plain_check"] = {k: answers(a, False) for k, a in ports.items()}
        run = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", app, "--speedup", "20", "--quiet",
                              "--timeout", "120", "--record", rec, "--address", lc.address],
                             capture_output=True, text=True, timeout=240)
        out["run"] = {"rc": run.returncode, "out": run.stdout[-3000:], "err": run.stderr[-3000:]}
        base = {k: v for k, v in os.environ.items() if k not in TLS_VARIABLES} | QUICK
        envs = {"tls": base | RayTLS.checked(crt, key, ca).environ(), "plain": base,
                "other_ca": base | RayTLS.checked(other_crt, other_key, other_ca).environ()}
        procs = {k: subprocess.Popen([sys.executable, "-c", CLIENT, lc.address], env=e, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True) for k, e in envs.items()}
        out["clients"] = {}
        for k, p in procs.items():
            try:
                so, se = p.communicate(timeout=90)
            except subprocess.TimeoutExpired:
                p.kill()
                so, se = p.communicate()
            out["clients"][k] = {"rc": p.returncode, "out": so[-1000:], "err": se[-4000:]}
    out["env_after"] = {v: os.environ.get(v) for v in TLS_VARIABLES}
    print("RESULT " + json.dumps(out))
''')


@pytest.mark.cluster
def test_a_mission_flies_on_a_tls_cluster_that_refuses_drivers_without_its_certificates(tmp_path):
    from aerodaas.recording.reader import summarize_mcap

    from tests.safety.tls_certs import ca_and_node

    (tmp_path / "ours").mkdir()
    (tmp_path / "other").mkdir()
    ours, other = ca_and_node(tmp_path / "ours"), ca_and_node(tmp_path / "other")
    rec = tmp_path / "farm.mcap"
    script = tmp_path / "tls_cluster.py"
    script.write_text(SCRIPT)
    # a clean environment: what earlier tests of this worker process left in os.environ (Ray's, the framework's
    # state variables) must not reach the cluster script (it timed out after other cluster tests, passed alone)
    keep = ("PATH", "HOME", "LANG", "LC_ALL", "TMPDIR", "PYTHONPATH", "VIRTUAL_ENV", "CI", "AERODAAS_DATA_DIR",
            "AERODAAS_MODEL_DIR")
    env = {k: os.environ[k] for k in keep if k in os.environ} | {"AERODAAS_NO_ATTACH": "1"}
    p = subprocess.run([sys.executable, str(script), *map(str, ours), *map(str, other),
                        str(REPO / "apps" / "farm_survey.py"), str(rec)],
                       cwd=tmp_path, capture_output=True, text=True, timeout=400, env=env)
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert p.returncode == 0 and line, p.stdout[-3000:] + p.stderr[-3000:]
    out = json.loads(line[len("RESULT "):])
    # every Ray process of the cluster got the variables; they are gone once the cluster is
    assert out["env"]["RAY_USE_TLS"] == "1" and out["env"]["RAY_TLS_CA_CERT"] == str(ours[0].resolve()), out["env"]
    assert all(v is None for v in out["env_after"].values()), out["env_after"]
    # the GCS and the raylet of each of the two nodes complete a TLS handshake with our certificate and speak
    # gRPC inside it, and answer no plain-text HTTP/2 client
    assert len(out["raylet_ports"]) == 2, out
    assert out["tls_check"] == {"gcs": "", "raylet0": "", "raylet1": ""}, out["tls_check"]
    assert all("is not a Ray cluster" in why for why in out["plain_check"].values()), out["plain_check"]
    # the mission flew on the TLS cluster (its driver inherited the variables)
    run = out["run"]
    assert run["rc"] == 0 and "mission outcome: success" in run["out"], run
    s = summarize_mcap(rec)
    assert s["finished"] and s["mission"]["outcome"] == "success" and s["mission"]["final_state"] == "LANDED", s
    counts = {c["schema"]: c["count"] for c in s["channels"]}
    assert counts["foxglove.PoseInFrame"] > 100, counts
    # a driver with our certificates joins (it sees both nodes); one without any, or with another authority's,
    # does not, although all three hold the cluster's token (RAY_AUTH_MODE=token, ~/.ray/auth_token)
    c = out["clients"]
    assert c["tls"]["rc"] == 0 and f"CONNECTED {out['raylet_ports']}" in c["tls"]["out"], c["tls"]
    for k in ("plain", "other_ca"):
        assert c[k]["rc"] not in (0, None) and "CONNECTED" not in c[k]["out"], (k, c[k])
        assert "Failed to connect to GCS" in c[k]["err"], (k, c[k])
    assert "Handshake failed" in c["other_ca"]["err"], c["other_ca"]  # refused in the TLS handshake itself


def test_ray_tls_files_are_checked_and_named(tmp_path):
    """No Ray: RayTLS.checked refuses a missing file, a key others may read and a certificate that is not the
    key's, naming the field and the file; from_environ is None without RAY_USE_TLS and names a missing variable."""
    from aerodaas.clusters.ray_tls import RayTLS

    from tests.safety.tls_certs import ca_and_node

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    ca, crt, key = ca_and_node(tmp_path / "a")
    _, other_crt, _ = ca_and_node(tmp_path / "b")
    assert RayTLS.checked(crt, key, ca).environ()["RAY_TLS_SERVER_KEY"] == str(key.resolve())
    with pytest.raises(ValueError, match=r"RayTLS\.ca '.*nope\.crt': not a readable regular file"):
        RayTLS.checked(crt, key, tmp_path / "nope.crt")
    with pytest.raises(ValueError, match=r"are not a certificate, its key and an authority"):
        RayTLS.checked(other_crt, key, ca)
    key.chmod(0o644)
    with pytest.raises(ValueError, match=r"RayTLS\.key .*mode 644.*chmod 600"):
        RayTLS.checked(crt, key, ca)
    assert RayTLS.from_environ({"RAY_USE_TLS": "0", "RAY_TLS_CA_CERT": str(ca)}) is None
    with pytest.raises(ValueError, match=r"RAY_TLS_SERVER_KEY is not set"):
        RayTLS.from_environ({"RAY_USE_TLS": "1", "RAY_TLS_SERVER_CERT": str(crt), "RAY_TLS_CA_CERT": str(ca)})


def test_run_address_with_ray_tls_half_set_exits_2_before_ray(tmp_path):
    """`aerodaas run --address` with RAY_USE_TLS=1 but no certificate variables: exit 2 naming them, before Ray."""
    import os

    app = tmp_path / "app.py"
    app.write_text("from aerodaas import *\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_TLS_")} | {"RAY_USE_TLS": "1"}
    p = run_cli("run", str(app), "--quiet", "--address", "127.0.0.1:1", cwd=REPO, env=env)  # in-process
    assert p.returncode == 2, p.stderr[-2000:]
    assert "RAY_USE_TLS=1 turns Ray's TLS on, but RAY_TLS_SERVER_CERT, RAY_TLS_SERVER_KEY, RAY_TLS_CA_CERT are not" \
           in p.stderr, p.stderr[-2000:]
    assert "Connecting to" not in p.stderr  # Ray was never asked
