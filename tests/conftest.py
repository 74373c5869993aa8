"""pytest wiring: hypothesis profiles, the real-image collection's folder, Ctrl-C as a user's
terminal delivers it, and fixtures of the images that ship with the tests (tests/data) or the
package.

Helpers that benches and users need too live in :mod:`phloem.testing`, not here.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

import phloem

DATA = Path(__file__).parent / "data"
# Set, not only found by phloem.testing, so that an installed phloem and the CLI tests'
# subprocesses look in the same place: ../shared/data beside this checkout.
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
os.environ.setdefault("PHLOEM_SHARED_DATA", str(SHARED))


@pytest.fixture(scope="session")
def bark() -> np.ndarray:
    """Embedded Douglas-fir bark, RGB float32 (256, 256, 3)."""
    return phloem.data.bark()[..., :3].copy()


@pytest.fixture(scope="session")
def water() -> np.ndarray:
    """Water photo, RGB float32 (300, 300, 3)."""
    return phloem.io.read_image(DATA / "water.jpg")


@pytest.fixture(scope="session")
def gravel() -> np.ndarray:
    """Gravel, gray float32 (128, 128)."""
    return phloem.io.read_image(DATA / "gravel_128.png")


def pytest_configure(config: pytest.Config) -> None:
    # A shell that starts pytest in the background (`pytest &`, or a runner without job control)
    # ignores SIGINT for it, and Python then raises no KeyboardInterrupt, nor do the CLI runs its
    # tests start, which inherit the disposition: the thirteen Ctrl-C tests failed that way.
    # They test what a user's Ctrl-C does, so they get the handler a terminal's Python has.
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    os.environ.setdefault("HYPOTHESIS_PROFILE", "fast")
    from hypothesis import settings

    settings.register_profile("fast", max_examples=25, deadline=None)
    settings.register_profile("slow", max_examples=200, deadline=None)
    settings.load_profile(os.environ["HYPOTHESIS_PROFILE"])
