"""A command's independent units of work, run here or on a Dask cluster (`--cluster`).

A command splits its work into units (a batch of sweep values of one scene, one measurement
file, one BRDF channel) and hands them to a `Pool`: `Pool.map(fn, units)` runs `fn` on each
and yields `(result, seconds)` in the units' order, with a progress bar over the units. The
local pool calls `fn` here, one unit after the other; a cluster pool submits every unit as a
task to a Dask scheduler at once (earlier units first), retries a task whose worker is lost
or which fails, and yields the results in order as they come back. The client (this
process) writes every file, so a run on a cluster writes the same files, the same way, as
one here. Leaving the `pool` block by an exception (Ctrl-C included) cancels every task it
submitted.

Each unit is the same computation in both places (the same function, the same array shapes),
so the outputs are the same bytes (`jaxskin.batch` makes a render's units so); a worker
compiles a configuration once and reuses it for every unit it gets.

Workers need jaxskin (the same version) and the files a scene names (meshes, materials,
layer images, BRDF files) at the same paths: a shared file system, as on any render farm.

    with pool("tcp://10.0.0.5:8786") as p:        # or pool(None): here
        for result, seconds in p.map(fn, units, desc="render", unit="batch"):
            ...                                    # in the units' order
"""

from __future__ import annotations

import contextlib
import functools
import re
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator

from .io import InputError

__all__ = ["Pool", "add_option", "check_address", "connect", "pool"]

CONNECT_TIMEOUT = 10.0  # seconds to reach the scheduler
RETRIES = 2  # times a failed task is tried again (a lost worker's tasks are resubmitted anyway)
INSTALL = "pip install 'jaxskin[cluster]'"
_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")


def check_address(text: str) -> str:
    """An argparse type: a scheduler address `tcp://host:port` (or `tls://…`)."""
    import argparse

    m = _ADDRESS.match(text.strip())
    if m is None or not 0 < int(m.group(3)) < 65536:
        raise argparse.ArgumentTypeError(
            f"expected a Dask scheduler address tcp://host:port, got {text!r}")
    return text.strip()


def add_option(parser, unit: str) -> None:
    """Add `--cluster ADDRESS` to a command's argparse parser; `unit` names its task."""
    parser.add_argument(
        "--cluster", type=check_address, default=None, metavar="ADDRESS",
        help=f"run the work on the Dask scheduler at ADDRESS (tcp://host:port), one task per "
        f"{unit}; the results come back and are written here, the same files as a local "
        f"run (needs {INSTALL}; workers need this jaxskin and the input files at the same "
        "paths)")


class Pool:
    """Where units run: here (`client` None) or on the Dask cluster of `client`."""

    def __init__(self, client=None, address: str | None = None):
        self.client, self.address = client, address
        self.futures: list = []

    def map(self, fn: Callable, units: Iterable, *, desc: str, unit: str = "task",
            retries: int = RETRIES) -> Iterator[tuple[object, float]]:
        """`fn(u)` for each unit `u`, yielded as `(result, seconds)` in the units' order;
        `seconds` is the time the unit took where it ran. Here: computed lazily, one unit
        when the caller asks for it. On a cluster: every unit submitted at once.

        **Arguments:**

        - `fn`: a picklable function of one unit (module-level, or a `functools.partial`).
        - `units`: the units, each picklable.
        - `desc`, `unit`: the progress bar's label and unit name.
        - `retries`: times a task that raised is tried again (cluster only).
        """
        from tqdm import tqdm

        units = list(units)
        bar = tqdm(total=len(units), desc=desc, unit=unit, disable=None)
        if self.client is None:
            return self._here(fn, units, bar)
        return self._there(fn, units, bar, retries)

    def mapper(self, *, desc: str, unit: str = "task") -> Callable:
        """`map` as a plain `map_units(fn, units)` → results in order (seconds dropped): the
        form a library function takes to run its units here or on a cluster
        (`fitting.brdf.fit(..., map_units=pool.mapper(desc="fit-brdf", unit="channel"))`)."""
        def map_units(fn, units):
            return (result for result, _ in self.map(fn, units, desc=desc, unit=unit))

        return map_units

    @staticmethod
    def _here(fn, units, bar):
        with bar, _ticking(bar):
            for u in units:
                out = _timed(fn, u)
                bar.update()
                yield out

    def _there(self, fn, units, bar, retries):
        from distributed import as_completed

        client = self.client
        futures = [client.submit(_timed_on_worker, fn, u, pure=False, retries=retries, priority=-i,
                                 key=f"jaxskin-{getattr(fn, '__name__', 'unit')}-{i}-"
                                     f"{time.time_ns()}")
                   for i, u in enumerate(units)]
        self.futures += futures
        index = {f.key: i for i, f in enumerate(futures)}
        ready: dict[int, tuple] = {}
        following = 0
        with bar, _ticking(bar):
            for f in as_completed(futures, loop=client.loop):
                try:
                    ready[index[f.key]] = f.result()  # a task's own exception is raised here
                except InputError as e:  # an input this process read but a worker could not
                    raise InputError(f"{e} (on a worker at {self.address}: the workers need "
                                     "the run's input files at the same paths)") from None
                f.release()
                bar.update()
                while following in ready:
                    yield ready.pop(following)
                    following += 1

    def cancel(self) -> None:
        """Cancel every task this pool submitted that has not finished."""
        pending = [f for f in self.futures if not f.done()]
        if pending and self.client is not None:
            with contextlib.suppress(Exception):
                self.client.cancel(pending, force=True)
        self.futures = []


def _timed(fn, unit):
    t0 = time.perf_counter()
    result = fn(unit)
    return result, time.perf_counter() - t0


def _timed_on_worker(fn, unit):
    _compile_cache_once()
    return _timed(fn, unit)


@contextlib.contextmanager
def pool(address: str | None = None, timeout: float | None = None) -> Iterator[Pool]:
    """A `Pool` here (`address` None) or on the Dask scheduler at `address`: connected
    within `timeout` seconds (default `CONNECT_TIMEOUT`) and checked (its workers run this
    jaxskin), or an `InputError` before any work. Leaving the block cancels what is still
    running and disconnects."""
    if address is None:
        yield Pool()
        return
    client = connect(address, timeout)
    p = Pool(client, address)
    try:
        yield p
    finally:
        p.cancel()
        with contextlib.suppress(Exception):
            client.close(timeout=5)


@contextlib.contextmanager
def _ticking(bar, every: float = 1.0):
    """Redraw `bar` every `every` seconds while the block runs: tqdm draws only on an update,
    so one long unit (a single scene at 1024², 30 s) would show `0/1 [00:00<?]` until it
    ended; this way its elapsed time counts."""
    import threading

    if bar.disable:
        yield
        return
    stop = threading.Event()

    def tick():
        while not stop.wait(every):
            with contextlib.suppress(Exception):
                bar.refresh()

    thread = threading.Thread(target=tick, daemon=True, name="jaxskin-progress")
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def _within(seconds: float, fn, cleanup):
    """`fn()`, or `TimeoutError` once `seconds` have passed: a server that accepts the
    connection and never answers holds `distributed.Client` past its own timeout for good.
    `fn` is then left to finish in a daemon thread, and `cleanup` is called on what it
    returns or raises (a client or an error) when it does: not leaked to a library caller
    who goes on."""
    import threading

    out: dict = {}
    lock = threading.Lock()

    def run():
        try:
            result = fn()
        except BaseException as e:  # noqa: BLE001  (handed to the caller, or cleaned up)
            result, key = e, "error"
        else:
            key = "value"
        with lock:
            if out.get("abandoned"):
                with contextlib.suppress(Exception):
                    cleanup(result)
                return
            out[key] = result

    thread = threading.Thread(target=run, daemon=True, name="jaxskin-connect")
    thread.start()
    thread.join(seconds)
    with lock:
        if not ("value" in out or "error" in out):
            out["abandoned"] = True
            raise TimeoutError(f"a connection was accepted, but no answer to Dask's "
                               f"handshake came back in {seconds:g} s")
    if "error" in out:
        raise out["error"]
    return out["value"]


def _close_late(cls, result) -> None:
    """What a connection that was given up on returned at last: a client, closed; an error,
    its half-made client dropped (`_drop_client`)."""
    if isinstance(result, cls):
        result.close(timeout=1)
    elif isinstance(result, BaseException):
        _drop_client(result, cls)


def _drop_client(error, cls) -> None:
    """Close, quickly and quietly, the half-made `distributed.Client` that `error` came out
    of (found in its traceback's frames): left to the garbage collector, its `__del__`
    closes it with a 20 s timeout and prints a traceback after our error line (a service
    that is not Dask at the address, say)."""
    tb = error.__traceback__
    while tb is not None:
        client = tb.tb_frame.f_locals.get("self")
        if isinstance(client, cls):
            with contextlib.suppress(Exception):
                client.close(timeout=1)
            with contextlib.suppress(Exception):
                client._Client__loop = None  # __del__: "failed early, nothing to do"
            break
        tb = tb.tb_next
    error.__traceback__ = None


def connect(address: str, timeout: float | None = None):
    """A `distributed.Client` on `address`, or an `InputError` saying why not: Dask missing,
    the scheduler not answering, workers without this jaxskin."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"--cluster needs Dask distributed: {INSTALL}") from None
    timeout = CONNECT_TIMEOUT if timeout is None else timeout
    import logging

    # A failed connection is our one error line, not distributed's log records as well.
    for name in ("distributed.client", "distributed.comm.tcp", "distributed.core"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    try:
        client = _within(timeout + 5.0, lambda: distributed.Client(
            address, timeout=timeout, set_as_default=False), functools.partial(
            _close_late, distributed.Client))
    except Exception as e:  # noqa: BLE001  (OSError, TimeoutError, comm errors: all unreachable)
        _drop_client(e, distributed.Client)
        why = " ".join(str(e).split())[:160] or e.__class__.__name__
        if isinstance(e, (OSError, TimeoutError)):
            raise InputError(f"--cluster: no Dask scheduler answered at {address} within "
                             f"{timeout:g} s ({why})") from None
        raise InputError(f"--cluster: what answers at {address} is not a Dask scheduler "
                         f"({e.__class__.__name__}: {why})") from None
    try:
        found = client.run(_versions)
    except Exception as e:  # noqa: BLE001  (a worker that cannot even unpickle our function)
        client.close()
        raise InputError(f"--cluster {address}: cannot ask the workers their jaxskin version "
                         f"({e.__class__.__name__}: {' '.join(str(e).split())[:160]}); install "
                         "this jaxskin on every worker") from None
    mine = _versions()
    wrong = {w: v for w, v in found.items() if v[0] != mine[0]}
    if wrong:
        client.close()
        worker, (version, _) = next(iter(wrong.items()))
        raise InputError(f"--cluster {address}: worker {worker} runs jaxskin {version}, this "
                         f"is {mine[0]}; install the same jaxskin on every worker")
    for worker, (_, jax_version) in found.items():
        if jax_version != mine[1]:
            warnings.warn(f"--cluster {address}: worker {worker} runs JAX {jax_version}, this "
                          f"process {mine[1]}: its images may differ in the last bits",
                          stacklevel=2)
            break
    if not found:
        print(f"jaxskin: note: the scheduler at {address} has no workers yet; the tasks wait "
              "for one", file=sys.stderr, flush=True)
    return client


def _versions() -> tuple[str, str]:
    """jaxskin's and JAX's versions where this runs (JAX's without importing it)."""
    from importlib.metadata import version

    from jaxskin import __version__ as v

    return v, version("jax")


@functools.cache
def _compile_cache_once() -> None:
    """A worker keeps compiled programs on disk like the command does (same switch): a
    worker that restarts, or the next run, loads them instead of compiling again."""
    from . import compile_cache

    compile_cache.enable()
