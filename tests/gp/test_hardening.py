"""Bad input to LaplaceGPC is refused up front, and Ctrl-C stops a long fit promptly."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from processes import default_signals

from aptkt.gp import LaplaceGPC

from .conftest import make_blobs

PYTHON_DIR = Path(__file__).resolve().parents[2] / "python"


def test_nan_in_y_is_an_error_not_a_class():
    X, _ = make_blobs(4, 2, 2, seed=0)
    y = np.array([0.0, 1.0, np.nan, 0.0, 1.0, 1.0, 0.0, np.nan])
    with pytest.raises(ValueError, match="NaN"):
        LaplaceGPC().fit(X, y)


@pytest.mark.parametrize("optimize", [False, True])
@pytest.mark.parametrize(
    "params,match",
    [
        ({"signal_variance": 1e300}, "signal_variance = 1.0000e300 lies outside its bounds"),
        ({"signal_variance": 1e-9}, "signal_variance .* lies outside"),
        ({"length_scale": 1e-9}, "length-scale of modality 0 .* lies outside"),
        ({"length_scale": [1.0, 1e7], "modalities": [[0], [1]]}, "modality 1 .* lies outside"),
        ({"length_scale": 50.0, "length_scale_bounds": (0.1, 10.0)}, "lies outside"),
    ],
)
def test_given_hyper_parameters_outside_their_bounds_are_errors(params, match, optimize):
    X, y = make_blobs(4, 2, 2, seed=1)
    with pytest.raises(ValueError, match=match):
        LaplaceGPC(optimize=optimize, fixed=("signal_variance", "length_scale"), **params).fit(X, y)


def test_starting_values_outside_the_bounds_are_errors():
    X, y = make_blobs(4, 2, 2, seed=1)
    with pytest.raises(ValueError, match="lies outside"):
        LaplaceGPC(optimize=False).fit(X, y, hyperparameters={1: {"length_scales": 1e9}})


def test_values_on_the_bounds_are_fine_and_data_scaled_starts_are_clamped():
    X, y = make_blobs(4, 2, 2, seed=1)
    model = LaplaceGPC(1e5, 1e-5, optimize=False).fit(X, y)
    assert model.length_scales_[0, 0] == pytest.approx(1e5)
    # "auto" on features in the millions: the data scale exceeds the default bound and is
    # clamped (it is no value the user gave).
    model = LaplaceGPC(optimize=False).fit(X * 1e7, y)
    assert model.length_scales_[0, 0] == pytest.approx(1e5)


@pytest.mark.parametrize("value", [np.nan, [1.0, np.nan], -1.0, 0.0, np.inf])
def test_bad_length_scales_are_errors(value):
    X, y = make_blobs(4, 2, 2, seed=2)
    mods = [[0], [1]] if np.ndim(value) else None
    with pytest.raises(ValueError, match="length_scale must be 'auto' or finite numbers > 0"):
        LaplaceGPC(length_scale=value, modalities=mods).fit(X, y)


CHILD = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from aptkt.gp import LaplaceGPC

    rng = np.random.default_rng(0)
    X = rng.normal(size=(1500, 6))
    y = (X[:, 0] + 0.5 * rng.normal(size=1500) > 0).astype(int) + (X[:, 1] > 0.7)
    model = LaplaceGPC(n_restarts=int(sys.argv[1]), max_iter=300, n_jobs=1, random_state=0)
    print("fitting", flush=True)
    try:
        model.fit(X, y)
    except KeyboardInterrupt:
        stamp = time.monotonic()
        # The interrupted fit's thread pool is kept: it must serve the next fit.
        LaplaceGPC(n_jobs=1, random_state=0).fit(X[:60], y[:60])
        print("interrupted", stamp, flush=True)
        sys.exit(0)
    print("finished", time.monotonic(), flush=True)
    """
)


@pytest.mark.skipif(os.name != "posix", reason="SIGINT delivery to a child process")
@pytest.mark.parametrize("restarts", [6, 1000], ids=["6 restarts", "MAX_RESTARTS"])
def test_ctrl_c_interrupts_a_long_fit_promptly(restarts):
    from aptkt.gp import MAX_RESTARTS

    assert restarts <= MAX_RESTARTS
    env = {**os.environ, "PYTHONPATH": str(PYTHON_DIR)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(restarts)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=default_signals,
    )
    try:
        assert child.stdout.readline().strip() == "fitting"
        time.sleep(1.0)  # well inside the fit (which takes far longer than a minute here)
        sent = time.monotonic()
        child.send_signal(signal.SIGINT)
        out, _ = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
    word, stamp = out.split()
    assert word == "interrupted", "the fit ran to its end instead of stopping on Ctrl-C"
    latency = float(stamp) - sent
    # The core checks its cancel flag between Newton iterations (a few tens of ms each at this
    # size); the bound is loose because the test machine may be loaded.
    assert latency < 3.0, f"Ctrl-C took {latency:.2f} s to stop the fit"


def _fit_in_child(X, y, write_end: int) -> None:
    """In a forked child: fit, send the probabilities to the parent, and leave at once."""
    status = 1
    try:
        proba = LaplaceGPC(n_jobs=1, random_state=0).fit(X, y).predict_proba(X)
        os.write(write_end, proba.astype(np.float64).tobytes())
        status = 0
    finally:
        os._exit(status)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX-only")
def test_a_process_forked_after_a_fit_fits_too():
    """The binding keeps its thread pools; a child forked after a fit has the parent's pools
    but not their threads, and must build its own instead of waiting on them for ever."""
    X, y = make_blobs(8, 3, 3, seed=5)
    expected = LaplaceGPC(n_jobs=1, random_state=0).fit(X, y).predict_proba(X)
    LaplaceGPC(n_jobs=2, optimize=False).fit(X, y)  # a second kept pool, of 2 threads
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read_end)
        _fit_in_child(X, y, write_end)
    os.close(write_end)
    deadline = time.monotonic() + 60
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            pytest.fail("the forked child's fit did not end within 60 s (waiting on pools?)")
        time.sleep(0.05)
    data = b""
    while chunk := os.read(read_end, 1 << 16):
        data += chunk
    os.close(read_end)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    got = np.frombuffer(data, dtype=np.float64).reshape(expected.shape)
    np.testing.assert_array_equal(got, expected)


def test_fits_from_several_threads_at_once_equal_fits_one_after_the_other():
    """Each calling thread has its own kept pool: concurrent fits neither block on each other
    for good nor mix their work."""
    import threading

    problems = [make_blobs(6, 3, 4, spread=s, seed=k) for k, s in enumerate((0.5, 1.0, 1.5))]
    alone = [LaplaceGPC(random_state=0).fit(X, y).predict_proba(X) for X, y in problems]
    together: list[np.ndarray | None] = [None] * len(problems)

    def fit(k: int) -> None:
        X, y = problems[k]
        together[k] = LaplaceGPC(random_state=0).fit(X, y).predict_proba(X)

    threads = [threading.Thread(target=fit, args=(k,)) for k in range(len(problems))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert not any(t.is_alive() for t in threads), "a concurrent fit did not end"
    for a, b in zip(alone, together):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("value", [np.nan, -1.0, np.inf, True])
def test_newton_tol_is_checked_like_optimizer_tol(value):
    # A NaN tolerance is never met: every Newton search ran to its iteration limit.
    X, y = make_blobs(4, 2, 2, seed=2)
    with pytest.raises(ValueError, match="newton_tol must be a finite number >= 0"):
        LaplaceGPC(newton_tol=value).fit(X, y)


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"max_jitter": np.nan}, "max_jitter must be a finite number >= 0"),
        ({"signal_variance": np.inf}, "signal_variance must be a finite number > 0"),
        ({"signal_variance": True}, "signal_variance must be a finite number > 0"),
        ({"length_scale_bounds": (1e-5, np.inf)}, "length_scale_bounds must be a finite"),
        ({"signal_variance_bounds": (2.0, 1.0)}, "signal_variance_bounds must satisfy low < high"),
        ({"modality_weights": [np.nan, 1.0]}, "modality_weights must be a finite number >= 0"),
        ({"max_iter": True}, "max_iter must be a non-negative integer"),
        ({"max_iter": 10**9}, "max_iter must be at most 1000000"),
        ({"newton_max_iter": 2.5}, "newton_max_iter must be a non-negative integer"),
    ],
)
def test_every_numeric_setting_is_checked(params, match):
    X, y = make_blobs(4, 2, 2, seed=2)
    mods = [[0], [1]] if "modality_weights" in params else None
    with pytest.raises(ValueError, match=match):
        LaplaceGPC(modalities=mods, **params).fit(X, y)


def test_n_restarts_is_bounded():
    """10**9 restarts took 12 GB for their starting points before the first start ran (and
    ignored Ctrl-C meanwhile); the count is refused before anything is allocated."""
    from aptkt.gp import MAX_RESTARTS

    X, y = make_blobs(4, 2, 2, seed=2)
    with pytest.raises(ValueError, match=f"n_restarts must be at most {MAX_RESTARTS}"):
        LaplaceGPC(n_restarts=10**9).fit(X, y)
    LaplaceGPC(n_restarts=MAX_RESTARTS, max_iter=1, random_state=0).fit(X[:20], y[:20])


def test_the_core_bounds_n_restarts_where_python_does(monkeypatch):
    """The bound lives in Python (aptkt.gp.MAX_RESTARTS) and in the Rust core; past Python's
    check the core refuses exactly one more."""
    from aptkt.gp import MAX_RESTARTS, settings

    X, y = make_blobs(4, 2, 2, seed=2)
    monkeypatch.setattr(settings, "MAX_RESTARTS", 10 * MAX_RESTARTS)
    with pytest.raises(ValueError, match=f"n_restarts must be at most {MAX_RESTARTS}, got"):
        LaplaceGPC(n_restarts=MAX_RESTARTS + 1, max_iter=1).fit(X[:20], y[:20])


THREADS_CHILD = textwrap.dedent(
    """
    import os
    import numpy as np
    from aptkt.gp import LaplaceGPC

    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 2))
    y = (X[:, 0] > 0).astype(int) + (X[:, 1] > 0)
    LaplaceGPC(n_jobs=10**6, random_state=0).fit(X, y).predict_proba(X)
    print(len(os.listdir("/proc/self/task")), flush=True)
    """
)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads in /proc")
def test_n_jobs_is_capped_at_the_cores():
    # Before the cap, n_jobs=10**6 kept starting threads (30,739 after 10 minutes).
    from aptkt.gp.arguments import threads

    cores = os.cpu_count() or 1
    assert threads(10**6) == cores and threads(-1) == cores
    env = {**os.environ, "PYTHONPATH": str(PYTHON_DIR)}
    r = subprocess.run(
        [sys.executable, "-c", THREADS_CHILD],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    # The interpreter's own threads (BLAS pools, ...) plus one pool of at most `cores`.
    baseline = subprocess.run(
        [
            sys.executable,
            "-c",
            "import os, numpy, aptkt.gp; print(len(os.listdir('/proc/self/task')))",
        ],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert int(r.stdout) <= int(baseline.stdout) + cores + 1, (r.stdout, baseline.stdout)


def test_a_fit_too_large_for_memory_says_so_before_allocating():
    """200,000 rows: a Rust allocation failure and "the fit's thread panicked" before; now a
    typed error naming the rows and the bytes, raised before any n x n matrix exists."""
    from aptkt.errors import AptktError, ProblemTooLargeError

    rng = np.random.default_rng(0)
    X = rng.normal(size=(200_000, 2))
    y = (X[:, 0] > 0).astype(int)
    with pytest.raises(ProblemTooLargeError, match="a fit on 200000 rows") as info:
        LaplaceGPC().fit(X, y)
    assert isinstance(info.value, AptktError)
    assert "TB of memory" in str(info.value) and "available" in str(info.value)
    # The shared kernel holds every classifier of every task at once: its estimate counts them
    # all, the further labelled data sets (kernel_tasks) included.
    with pytest.raises(ProblemTooLargeError, match="a shared-kernel fit on 200000 rows"):
        LaplaceGPC(kernel="shared").fit(X, y)
    with pytest.raises(ProblemTooLargeError, match="a shared-kernel fit on 200020 rows"):
        LaplaceGPC().fit(X[:20], y[:20], kernel_tasks=[(X, y)])
    from aptkt.gp import kernel_matrix

    with pytest.raises(ProblemTooLargeError, match="kernel matrix of 200000 rows"):
        kernel_matrix(X, [0.0, 0.0])
