"""A property-based fuzz of the studio's API from its own OpenAPI document (schemathesis): for a
bounded number of generated requests per operation, with and without valid values, no answer is
a 5xx."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

import phloem
from phloem.studio import TOKEN_HEADER, Project, create_app

from .conftest import TOKEN

schemathesis = pytest.importorskip("schemathesis", reason="schemathesis is not installed")
from schemathesis.checks import not_a_server_error  # noqa: E402

# The schema is loaded when the module is collected (schemathesis parametrizes at import), so the
# project lives in a temporary folder of the module's own, removed after its tests.
_folder = tempfile.TemporaryDirectory(prefix="phloem-studio-fuzz-")
_root = Path(_folder.name)
phloem.io.write_image(_root / "a.png", phloem.data.bark()[:32, :32, :3])
# Small limits, so that a generated size or upload is refused early instead of computed.
_app = create_app(Project(_root, max_pixels=10_000, max_upload_bytes=20_000, max_memory=2**26), token=TOKEN, threads=1)
schema = schemathesis.openapi.from_asgi("/openapi.json", _app, headers={TOKEN_HEADER: TOKEN})


@pytest.fixture(scope="module", autouse=True)
def _cleanup() -> Iterator[None]:
    yield
    _app.state.jobs.shutdown()
    _folder.cleanup()


@schema.parametrize()
@settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_no_request_is_a_server_error(case):
    case.call_and_validate(headers={TOKEN_HEADER: TOKEN}, checks=[not_a_server_error])
