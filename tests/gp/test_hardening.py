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
    model = LaplaceGPC(n_restarts=6, max_iter=300, n_jobs=1, random_state=0)
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
def test_ctrl_c_interrupts_a_long_fit_promptly():
    env = {**os.environ, "PYTHONPATH": str(PYTHON_DIR)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True, env=env
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
