"""`--cluster`: render, calibrate, fit-brdf, fit-skin and fit-image on a Dask cluster write
the same bytes as a local run; a worker killed mid-run is survived; a bad address is one
line, exit 2; a sweep sharded over two local devices gives the same bytes as one device.

One `LocalCluster` (2 worker processes, 1 thread each) serves the module: starting it and
the workers' first JAX import take seconds.
"""

import contextlib
import hashlib
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from jaxskin import batch, cluster
from jaxskin.cli import main

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parent.parent
SMALL = ["-D", "texture.size=64", "-D", "camera.size=64"]


@pytest.fixture(scope="module")
def dask_cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.CRITICAL) as lc, \
            distributed.Client(lc, set_as_default=False) as client:
        yield lc, client


def digests(folder) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(folder).iterdir())}


def run_both(tmp_path, capsys, address, args) -> tuple[dict, dict]:
    """`args` (with `-o` added) run here and on the cluster: the two folders' digests, after
    checking both runs exit 0 and print the same files and scene rows (time aside)."""
    out = []
    for where, extra in (("local", []), ("cluster", ["--cluster", address])):
        assert main([*args, "-o", str(tmp_path / where), *extra]) == 0
        text = capsys.readouterr().out.replace(str(tmp_path / where), "OUT")
        out.append([line.rsplit(None, 1)[0] if line[:1] != " " else line
                    for line in text.splitlines()])
    assert out[0] == out[1]
    return digests(tmp_path / "local"), digests(tmp_path / "cluster")


@pytest.mark.slow  # 37 s under a load of 10 on 2 cores (two compiles per worker)
def test_sweep_and_two_scenes_on_the_cluster_match_the_local_bytes(tmp_path, capsys,
                                                                    dask_cluster):
    """A sweep of 10 (two batches: 8, and 2 padded to 8) and two plain scenes with their
    maps and GLB (made on the workers too); every file byte-identical to the local run's."""
    lc, _ = dask_cluster
    local, there = run_both(tmp_path / "sweep", capsys, lc.scheduler_address,
                            ["render", "hand", *SMALL, "--sweep", "material.melanin=0:1:10"])
    assert len(local) == 10 and local == there
    local, there = run_both(tmp_path / "scenes", capsys, lc.scheduler_address,
                            ["render", "hand", "foot", *SMALL, "--maps", "--glb"])
    assert len(local) == 10 and local == there  # image, glb, height, normal, field each
    assert "foot_texture.size-64_camera.size-64_normal.png" in local
    # Different scenes, different files: the comparison compares something.
    assert len(set(local.values())) == 10


def test_a_worker_killed_mid_run_has_its_task_retried_and_the_run_completes(
        tmp_path, capsys, dask_cluster, monkeypatch):
    """The first task to start kills its own worker process (SIGKILL, mid-task): the
    scheduler runs it again elsewhere and every file matches the local run's."""
    lc, client = dask_cluster
    args = ["render", "hand", *SMALL, "--sweep", "material.melanin=0:1:24"]
    assert main([*args, "-o", str(tmp_path / "local")]) == 0
    before = set(client.run(os.getpid).values())
    marker = str(tmp_path / "a worker died")
    render_unit = batch.render_unit

    def dies_once(unit):  # a closure: pickled by value, run on the worker
        # O_EXCL: exactly one task dies. A check-then-create would let the first tasks of
        # both workers, started together, both find no marker and both die (2 deaths, not 1).
        try:
            os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return render_unit(unit)
        os.kill(os.getpid(), signal.SIGKILL)

    monkeypatch.setattr(batch, "render_unit", dies_once)
    assert main([*args, "-o", str(tmp_path / "cluster"), "--cluster",
                 lc.scheduler_address]) == 0
    assert os.path.exists(marker)
    assert len(digests(tmp_path / "local")) == 24
    assert digests(tmp_path / "cluster") == digests(tmp_path / "local")
    client.wait_for_workers(2, timeout=60)  # the nanny restarts it, for the next tests
    assert len(before - set(client.run(os.getpid).values())) == 1  # one process did die
    capsys.readouterr()


def test_ctrl_c_cancels_the_tasks_on_the_cluster(tmp_path, capsys, dask_cluster,
                                                 monkeypatch):
    """SIGINT (KeyboardInterrupt) when the first image is being written: exit 130, the line
    names no file, and the scheduler is left with no task of the run."""
    from jaxskin import maps

    lc, client = dask_cluster

    def interrupted(*a, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(maps, "write_render", interrupted)
    rc = main(["render", "hand", *SMALL, "--sweep", "material.melanin=0:1:40", "-o",
               str(tmp_path / "out"), "--cluster", lc.scheduler_address])
    err = capsys.readouterr().err.splitlines()
    assert rc == 130 and err == ["jaxskin: interrupted (SIGINT) while rendering hand; no file "
                                 "was written"]

    def tasks(dask_scheduler):
        return [str(k) for k in dask_scheduler.tasks if "jaxskin-" in str(k)]

    deadline = time.monotonic() + 10
    while client.run_on_scheduler(tasks) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert client.run_on_scheduler(tasks) == []
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


def test_an_input_a_worker_cannot_read_is_named_with_the_reason(tmp_path, capsys,
                                                                 dask_cluster, monkeypatch):
    """A worker without the run's files (no shared file system) raises the reader's
    InputError there: one line that names the file and says what workers need; exit 2."""
    lc, _ = dask_cluster

    def cannot_read(unit):  # a closure: pickled by value, raises on the worker
        from jaxskin.io import InputError

        raise InputError("no such file", "/shared/meshes/head.obj")

    monkeypatch.setattr(batch, "render_unit", cannot_read)
    rc = main(["render", "hand", *SMALL, "-o", str(tmp_path / "out"), "--cluster",
               lc.scheduler_address])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and err == [f"jaxskin: error: /shared/meshes/head.obj: no such file (on a "
                               f"worker at {lc.scheduler_address}: the workers need the run's "
                               "input files at the same paths)"]


@pytest.mark.slow  # 21 s under a load of 10 on 2 cores
def test_calibrate_on_the_cluster_matches_the_local_bytes(tmp_path, capsys, dask_cluster):
    """Two measurement files of one shape (one compiled fit), two tasks (the reports are drawn here from the results, so
    the JSON decides; --no-report keeps the test short)."""
    lc, _ = dask_cluster
    files = [str(ROOT / "data" / "measurements" / f"{n}.csv")
             for n in ("foundation_light", "foundation_dark")]
    local, there = run_both(tmp_path, capsys, lc.scheduler_address,
                            ["calibrate", *files, "--no-report"])
    assert sorted(local) == ["foundation_dark.json", "foundation_light.json"] and local == there


def test_fit_brdf_on_the_cluster_matches_the_local_bytes(tmp_path, capsys, dask_cluster):
    """A 1-lobe fit to 60 samples: three channel tasks; the same JSON, byte for byte."""
    lc, _ = dask_cluster
    rng = np.random.default_rng(1)
    rows = ["theta_in_deg,phi_in_deg,theta_out_deg,phi_out_deg,R,G,B"]
    for _ in range(60):
        ti, to, po = rng.uniform(0, 80), rng.uniform(0, 80), rng.uniform(0, 360)
        lobe = np.exp(-((ti - to) / 20) ** 2) * np.array([0.5, 0.4, 0.3])
        rows.append(f"{ti},0,{to},{po}," + ",".join(f"{0.2 + v:.6f}" for v in lobe))
    (tmp_path / "s.csv").write_text("\n".join(rows) + "\n")
    outs = []
    for where, extra in (("local", []), ("cluster", ["--cluster", lc.scheduler_address])):
        assert main(["fit-brdf", str(tmp_path / "s.csv"), "--lobes", "1", "--starts", "2",
                     "--no-report", "-o", str(tmp_path / where / "fit.json"), *extra]) == 0
        outs.append(digests(tmp_path / where))
    assert list(outs[0]) == ["fit.json"] and outs[0] == outs[1]
    capsys.readouterr()


@pytest.mark.slow  # a float64 LM compile on each worker: about a minute under load
def test_fit_skin_on_the_cluster_matches_the_local_bytes(tmp_path, capsys, dask_cluster):
    """12 NIST subjects, two chunks of 10 (the second padded): two tasks; the same twelve_fit.csv."""
    from jaxskin import formats

    lc, _ = dask_cluster
    names, wl, R = formats.read_spectra(formats.data_dir() / "spectra" / formats.NIST_FILE)
    rows = ["wavelength_nm," + ",".join(names[:12])]
    rows += [f"{x:g}," + ",".join(f"{r:.4f}" for r in R[:12, i]) for i, x in enumerate(wl)]
    (tmp_path / "twelve.csv").write_text("\n".join(rows) + "\n")
    outs = []
    for where, extra in (("local", []), ("cluster", ["--cluster", lc.scheduler_address])):
        assert main(["fit-skin", str(tmp_path / "twelve.csv"), "--starts", "2", "--no-report",
                     "-o", str(tmp_path / where), *extra]) == 0
        outs.append(digests(tmp_path / where))
    assert list(outs[0]) == ["twelve_fit.csv"] and outs[0] == outs[1]
    assert (tmp_path / "local" / "twelve_fit.csv").read_text().count("\n") == 13
    capsys.readouterr()


def exit_code(argv) -> int:
    try:
        return main(argv)
    except SystemExit as e:  # argparse's one-line errors
        return e.code


@pytest.mark.parametrize("address, why", [
    ("tcp://127.0.0.1:9", "no Dask scheduler answered at tcp://127.0.0.1:9 within 2 s"),
    ("localhost:8786", "expected a Dask scheduler address tcp://host:port, got 'localhost:8786'"),
    ("tcp://127.0.0.1:99999", "expected a Dask scheduler address"),
])
def test_a_bad_address_is_one_line_and_exit_2_before_any_work(tmp_path, capsys, monkeypatch,
                                                              address, why):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", 2.0)
    rc = exit_code(["render", "hand", "-o", str(tmp_path / "out"), "--cluster", address])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("jaxskin: error: "), err
    assert why in err[0]
    assert not (tmp_path / "out").exists()


def test_workers_with_another_jaxskin_are_refused_before_any_work(tmp_path, capsys,
                                                                  dask_cluster, monkeypatch):
    """This process claims another version than the workers report: exit 2, one line."""
    lc, _ = dask_cluster
    import jaxskin

    real = cluster._versions()
    monkeypatch.setattr(jaxskin, "__version__", "9.9.9")  # here only: workers import theirs
    rc = main(["render", "hand", "-o", str(tmp_path / "out"), "--cluster",
               lc.scheduler_address])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and f"runs jaxskin {real[0]}, this is 9.9.9" in err[0]
    assert not (tmp_path / "out").exists()


def test_without_dask_the_option_says_what_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed → ImportError
    rc = main(["calibrate", str(ROOT / "data" / "measurements" / "blush_rose.csv"), "-o",
               str(tmp_path / "out"), "--cluster", "tcp://127.0.0.1:8786"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and err == ["jaxskin: error: --cluster needs Dask distributed: pip install "
                               "'jaxskin[cluster]'"]
    assert not (tmp_path / "out").exists()


SHARDED = """
import jax, sys
from jaxskin import batch
from jaxskin.cli import main
assert len(jax.devices()) == 2, jax.devices()
values, replicated = batch.shard_sweep([0.0, 0.5, 1.0])
assert values.shape == (4,) and len(values.sharding.device_set) == 2 and replicated is not None
sys.exit(main(sys.argv[1:]))
"""


def test_a_sweep_sharded_over_two_devices_matches_one_device(tmp_path, capsys):
    """XLA_FLAGS gives the subprocess two CPU devices (it must be set before JAX starts):
    a sweep of 5 (padded to 8, 4 per device) writes the bytes this one-device process does."""
    args = ["render", "hand", *SMALL, "--sweep", "material.melanin=0.1:0.9:5"]
    assert main([*args, "-o", str(tmp_path / "one")]) == 0
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2"
    env = {**os.environ, "XLA_FLAGS": flags.strip()}  # compiled as this process compiles
    proc = subprocess.run([sys.executable, "-c", SHARDED, *args, "-o", str(tmp_path / "two")],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    one = digests(tmp_path / "one")
    assert len(one) == 5 and digests(tmp_path / "two") == one
    capsys.readouterr()


@pytest.mark.slow  # a compile of the fit on a worker
def test_fit_image_on_the_cluster_matches_the_local_bytes(tmp_path, capsys, dask_cluster):
    """The whole fit as one task on a worker: the same fitted scene TOML as here (the
    report's title holds the time, so it is compared by its size only)."""
    import imageio.v3 as iio

    lc, _ = dask_cluster
    small = ["-D", "texture.size=32", "-D", "camera.size=32"]
    assert main(["render", "hand", *small, "-D", "material.melanin=0.45",
                 "-o", str(tmp_path / "target")]) == 0
    target, = (tmp_path / "target").glob("*.png")
    outs = []
    for where, extra in (("local", []), ("cluster", ["--cluster", lc.scheduler_address])):
        assert main(["fit-image", "hand", str(target), "--fit", "material.melanin",
                     "--steps", "6", *small, "-o", str(tmp_path / where), *extra]) == 0
        outs.append(digests(tmp_path / where))
    capsys.readouterr()
    assert sorted(outs[0]) == ["hand.toml", "hand_fit.png"]
    assert outs[0]["hand.toml"] == outs[1]["hand.toml"]
    assert (iio.imread(tmp_path / "local" / "hand_fit.png").shape
            == iio.imread(tmp_path / "cluster" / "hand_fit.png").shape)
    assert "material.melanin" in (tmp_path / "cluster" / "hand.toml").read_text()


@pytest.mark.parametrize("reply, why", [
    (b"HTTP/1.1 400 Bad Request\r\n\r\n", "is not a Dask scheduler ("),
    (None, "no Dask scheduler answered at tcp://127.0.0.1:{port} within 1 s (a connection "
           "was accepted, but no answer to Dask's handshake came back in 6 s)"),
])
def test_a_service_that_is_not_dask_is_one_line_and_exit_2(tmp_path, reply, why):
    """An HTTP server at the address must not print distributed's traceback after our line
    and take 22 s; a server that accepts and never answers must not hold the command for
    good. Both are one line, exit 2, within the timeout and a few seconds."""
    import socket
    import threading

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    held = []

    def serve():
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                if reply is not None:
                    conn.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    code = ("import sys; from jaxskin import cluster; cluster.CONNECT_TIMEOUT = 1.0; "
            "from jaxskin.cli import main; sys.exit(main(sys.argv[1:]))")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code, "render", "hand", "-o",
                           str(tmp_path / "out"), "--cluster", f"tcp://127.0.0.1:{port}"],
                          capture_output=True, text=True, timeout=120)
    seconds = time.perf_counter() - t0
    server.close()
    err = proc.stderr.splitlines()
    assert proc.returncode == 2 and len(err) == 1, proc.stderr
    assert err[0].startswith("jaxskin: error: --cluster: ") and why.format(port=port) in err[0]
    assert seconds < 60, seconds
    assert not (tmp_path / "out").exists()


def test_a_connection_given_up_on_is_closed_when_it_ends():
    """`_within` leaves `fn` running when it gives up; what `fn` returns or raises later is
    handed to `cleanup`, not leaked (an IO loop thread would outlive `connect`)."""
    import threading

    done, cleaned = threading.Event(), []

    def slow():
        done.wait(5)
        return "client"

    with pytest.raises(TimeoutError, match="no answer to Dask's handshake came back in 0.2 s"):
        cluster._within(0.2, slow, cleaned.append)
    done.set()
    for _ in range(100):
        if cleaned:
            break
        time.sleep(0.02)
    assert cleaned == ["client"]
    assert cluster._within(1.0, lambda: 7, cleaned.append) == 7 and cleaned == ["client"]


def test_a_long_unit_keeps_its_progress_bar_counting():
    """tqdm draws only on an update: one long unit (a single scene) shows `0/1 [00:00<?]`
    until it ends. `_ticking` redraws the bar while the work runs, and stops."""
    class Bar:
        disable, refreshed = False, 0

        def refresh(self):
            self.refreshed += 1

    bar = Bar()
    with cluster._ticking(bar, every=0.05):
        time.sleep(0.3)
    seen = bar.refreshed
    assert seen >= 3, seen
    time.sleep(0.15)
    assert bar.refreshed == seen  # stopped with the block
    off = Bar()
    off.disable = True
    with cluster._ticking(off, every=0.01):
        time.sleep(0.05)
    assert off.refreshed == 0
