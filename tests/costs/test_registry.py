"""The backend registry (``quilting.costs.registry``) and ``auto``'s safety net
(``quilting.costs.fallback``), without needing a GL context.

The GL module is replaced by a fake in ``sys.modules`` (or made unimportable), so every case
(no moderngl, no GPU device, no context, a software rasterizer, a hardware GPU) runs on any
machine; ``tests/costs/test_gl.py`` runs the real thing where a context exists. Checked here:
the names and their validation (errors name every choice), ``QUILTING_BACKEND``, what ``auto``
stands for and why, the statuses of ``gl_status`` and ``available_backends``,
``backend_renderer``, the classes ``get_backend`` returns, and :class:`FallbackBackend`
switching to its secondary, with the job, at start or mid-job, only on a ``BackendError``.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import pytest
from numpy.typing import NDArray

import quilting.backends
import quilting.costs
from quilting.core.errors import BackendError, InvalidParameterError
from quilting.core.fields import CostBackend, CostRequest, FieldBatch, Shortlist
from quilting.costs import registry
from quilting.costs.fallback import FallbackBackend
from quilting.costs.fft import FFTBackend
from quilting.costs.reference import ReferenceBackend

GL_MODULE = "quilting.costs.gl"


@pytest.fixture(autouse=True)
def no_operator_override(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test starts without ``QUILTING_BACKEND`` (the machine's own setting must not leak)."""
    monkeypatch.delenv(registry.BACKEND_VARIABLE, raising=False)


# --------------------------------------------------------------------------------------------
# A fake GL module: the registry imports `quilting.costs.gl` lazily, so one in sys.modules
# (and as the package's attribute) stands for the real one.
# --------------------------------------------------------------------------------------------


@dataclass
class FakeInfo:
    renderer: str
    software: bool


class FakeGLBackend:
    """A GL backend that starts (or not) as the fake module says."""

    name = "gl"

    def __init__(self) -> None:
        if FakeGL.start_error is not None:
            raise BackendError(FakeGL.start_error)
        self.renderer = FakeGL.renderer


class FakeGL:
    """What the fake module reports; tests set these."""

    nodes: ClassVar[list[str]] = []
    renderer: ClassVar[str] = "Fake GPU 9000"
    software: ClassVar[bool] = False
    probe_error: ClassVar[str | None] = None
    start_error: ClassVar[str | None] = None
    probes: ClassVar[int] = 0


def _fake_module() -> types.ModuleType:
    module = types.ModuleType(GL_MODULE)

    def gpu_device_nodes() -> list[str]:
        return list(FakeGL.nodes)

    def probe(index: int | None = None) -> FakeInfo:
        FakeGL.probes += 1
        if FakeGL.probe_error is not None:
            raise BackendError(FakeGL.probe_error)
        return FakeInfo(FakeGL.renderer, FakeGL.software)

    module.gpu_device_nodes = gpu_device_nodes  # type: ignore[attr-defined]
    module.probe = probe  # type: ignore[attr-defined]
    module.GLBackend = FakeGLBackend  # type: ignore[attr-defined]
    return module


@pytest.fixture
def fake_gl(monkeypatch: pytest.MonkeyPatch) -> Iterator[type[FakeGL]]:
    """The fake GL module in place of the real one, reset to 'a hardware GPU that works'."""
    monkeypatch.setattr(FakeGL, "nodes", ["/dev/nvidia0"])
    monkeypatch.setattr(FakeGL, "renderer", "Fake GPU 9000")
    monkeypatch.setattr(FakeGL, "software", False)
    monkeypatch.setattr(FakeGL, "probe_error", None)
    monkeypatch.setattr(FakeGL, "start_error", None)
    monkeypatch.setattr(FakeGL, "probes", 0)
    module = _fake_module()
    monkeypatch.setitem(sys.modules, GL_MODULE, module)
    monkeypatch.setattr(quilting.costs, "gl", module, raising=False)
    yield FakeGL


@pytest.fixture
def no_moderngl(monkeypatch: pytest.MonkeyPatch) -> None:
    """``quilting.costs.gl`` cannot be imported (as without the ``gl`` extra)."""
    # None in sys.modules makes `import` raise ImportError; the package attribute must go too,
    # or `from quilting.costs import gl` would find it there.
    monkeypatch.setitem(sys.modules, GL_MODULE, None)
    monkeypatch.delattr(quilting.costs, "gl", raising=False)


# --------------------------------------------------------------------------------------------
# Names
# --------------------------------------------------------------------------------------------


def test_the_names_and_their_public_home() -> None:
    assert registry.BACKEND_NAMES == ("auto", "fft", "gl", "reference")
    assert registry.BACKEND_VARIABLE == "QUILTING_BACKEND"
    # quilting.backends is what the service and the CLI use: the very same objects.
    for name in quilting.backends.__all__:
        assert getattr(quilting.backends, name) is getattr(registry, name), name


@pytest.mark.parametrize("name", ["fft", "gl", "reference"])
def test_a_concrete_name_stands_for_itself(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    assert registry.resolve_name(name) == name
    # The operator's variable is about `auto` only.
    monkeypatch.setenv(registry.BACKEND_VARIABLE, "reference" if name != "reference" else "fft")
    assert registry.resolve_name(name) == name


@pytest.mark.parametrize("name", ["", "cuda", "FFT", " fft", "Auto", "opengl"])
@pytest.mark.parametrize(
    "call", [registry.resolve_name, registry.get_backend, registry.backend_renderer]
)
def test_unknown_names_are_refused_naming_the_choices(
    call: Callable[[str], Any], name: str
) -> None:
    with pytest.raises(InvalidParameterError) as caught:
        call(name)
    error = caught.value
    assert error.parameter == "backend" and error.value == name
    for choice in registry.BACKEND_NAMES:
        assert repr(choice) in str(error), choice
    assert error.code == "invalid_parameter"


# --------------------------------------------------------------------------------------------
# QUILTING_BACKEND and what auto stands for
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("forced", ["fft", "gl", "reference", "  reference \n"])
def test_the_variable_decides_auto(forced: str, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_status(create_context: bool = True) -> registry.BackendStatus:
        raise AssertionError("auto looked at the GPU although QUILTING_BACKEND decides")

    monkeypatch.setattr(registry, "gl_status", no_status)
    monkeypatch.setenv(registry.BACKEND_VARIABLE, forced)
    concrete, why = registry.auto_choice()
    assert concrete == forced.strip()
    assert why == f"QUILTING_BACKEND={forced.strip()}"
    assert registry.resolve_name("auto") == forced.strip()


@pytest.mark.parametrize("value", ["", "   ", "auto"])
def test_an_empty_or_auto_variable_is_no_override(
    value: str, fake_gl: type[FakeGL], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(registry.BACKEND_VARIABLE, value)
    assert registry.auto_choice() == ("gl", "hardware GPU: Fake GPU 9000")


@pytest.mark.parametrize("value", ["cuda", "FFT", "auto,gl"])
def test_a_bad_variable_is_refused_by_its_name(value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(registry.BACKEND_VARIABLE, value)
    for call in (registry.auto_choice, lambda: registry.resolve_name("auto")):
        with pytest.raises(InvalidParameterError) as caught:
            call()
        assert caught.value.parameter == "QUILTING_BACKEND" and caught.value.value == value
        assert "'fft'" in str(caught.value) and "'reference'" in str(caught.value)


def test_auto_on_a_hardware_gpu_is_gl(fake_gl: type[FakeGL]) -> None:
    assert registry.auto_choice() == ("gl", "hardware GPU: Fake GPU 9000")
    assert registry.resolve_name("auto") == "gl"


def test_auto_on_a_software_rasterizer_is_fft(fake_gl: type[FakeGL]) -> None:
    fake_gl.software, fake_gl.renderer = True, "llvmpipe (LLVM 17, 256 bits)"
    concrete, why = registry.auto_choice()
    assert concrete == "fft"
    assert "software rasterizer" in why and "llvmpipe" in why


def test_auto_without_a_gpu_device_makes_no_context(fake_gl: type[FakeGL]) -> None:
    # The cheap answer: no device file, no probe (a context costs seconds on llvmpipe).
    fake_gl.nodes = []
    concrete, why = registry.auto_choice()
    assert concrete == "fft" and "no GPU device" in why
    assert fake_gl.probes == 0


def test_auto_when_the_context_fails_is_fft(fake_gl: type[FakeGL]) -> None:
    fake_gl.probe_error = "no OpenGL 4.3 context on EGL device 0: boom"
    assert registry.auto_choice() == ("fft", "no OpenGL 4.3 context on EGL device 0: boom")


def test_auto_without_moderngl_is_fft(no_moderngl: None) -> None:
    concrete, why = registry.auto_choice()
    assert concrete == "fft" and "moderngl is not installed" in why


# --------------------------------------------------------------------------------------------
# gl_status and available_backends
# --------------------------------------------------------------------------------------------


def test_gl_status_in_every_situation(fake_gl: type[FakeGL]) -> None:
    hardware = registry.gl_status()
    assert (hardware.name, hardware.available, hardware.preferred) == ("gl", True, True)
    assert hardware.renderer == "Fake GPU 9000" and "auto uses gl" in hardware.reason

    fake_gl.software, fake_gl.renderer = True, "llvmpipe"
    software = registry.gl_status()
    assert software.available and not software.preferred and software.renderer == "llvmpipe"
    assert "software rasterizer" in software.reason and "auto uses fft" in software.reason

    fake_gl.probe_error = "driver says no"
    failed = registry.gl_status()
    assert not failed.available and not failed.preferred and failed.renderer is None
    assert failed.reason == "driver says no"

    # No device: with a context asked for it is still tried (llvmpipe needs no device) ...
    fake_gl.nodes, fake_gl.probe_error = [], None
    probes = fake_gl.probes
    assert registry.gl_status(create_context=True).available
    assert fake_gl.probes == probes + 1
    # ... without, it is not.
    cheap = registry.gl_status(create_context=False)
    assert not cheap.available and "no GPU device" in cheap.reason
    assert fake_gl.probes == probes + 1


def test_gl_status_without_moderngl(no_moderngl: None) -> None:
    for create_context in (True, False):
        status = registry.gl_status(create_context)
        assert not status.available and not status.preferred and status.renderer is None
        assert "moderngl is not installed" in status.reason and "quilting[gl]" in status.reason


def test_available_backends_lists_every_concrete_name(fake_gl: type[FakeGL]) -> None:
    fake_gl.software, fake_gl.renderer = True, "llvmpipe"
    statuses = registry.available_backends()
    assert [s.name for s in statuses] == ["fft", "gl", "reference"]
    assert sorted(s.name for s in statuses) == sorted(set(registry.BACKEND_NAMES) - {"auto"})
    by_name = {s.name: s for s in statuses}
    for cpu in ("fft", "reference"):
        assert by_name[cpu].available and by_name[cpu].renderer == "cpu" and by_name[cpu].reason
    assert by_name["gl"] == registry.gl_status(create_context=True)
    assert by_name["gl"].renderer == "llvmpipe"  # the context was made to name it


@pytest.mark.parametrize("situation", ["no GPU", "software", "hardware", "variable"])
def test_preferred_marks_exactly_what_auto_picks(
    situation: str, fake_gl: type[FakeGL], monkeypatch: pytest.MonkeyPatch
) -> None:
    # BackendStatus.preferred is documented as "True when auto picks this backend here":
    # on any machine, exactly one status is preferred, the one auto_choice names.
    if situation == "no GPU":  # no device file; Mesa may still make a llvmpipe context
        fake_gl.nodes, fake_gl.software, fake_gl.renderer = [], True, "llvmpipe"
    elif situation == "software":
        fake_gl.software, fake_gl.renderer = True, "llvmpipe"
    elif situation == "variable":
        monkeypatch.setenv(registry.BACKEND_VARIABLE, "reference")
    picked = registry.auto_choice()[0]
    preferred = [s.name for s in registry.available_backends() if s.preferred]
    assert preferred == [picked]


# --------------------------------------------------------------------------------------------
# backend_renderer
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["fft", "reference"])
def test_cpu_backends_run_on_the_cpu(name: str, fake_gl: type[FakeGL]) -> None:
    assert registry.backend_renderer(name) == (name, "cpu", "asked for by name")
    assert fake_gl.probes == 0  # asking for a CPU backend never makes a context


def test_gl_by_name_names_its_renderer_or_why_not(fake_gl: type[FakeGL]) -> None:
    fake_gl.software, fake_gl.renderer = True, "llvmpipe"
    assert registry.backend_renderer("gl") == ("gl", "llvmpipe", "asked for by name")
    fake_gl.probe_error = "no OpenGL 4.3 context on EGL device 0"
    assert registry.backend_renderer("gl") == (
        "gl",
        None,
        "no OpenGL 4.3 context on EGL device 0",
    )


def test_auto_renderer_follows_auto(fake_gl: type[FakeGL], monkeypatch: pytest.MonkeyPatch) -> None:
    assert registry.backend_renderer("auto") == (
        "gl",
        "Fake GPU 9000",
        "hardware GPU: Fake GPU 9000",
    )
    fake_gl.nodes = []
    backend, renderer, why = registry.backend_renderer("auto")
    assert (backend, renderer) == ("fft", "cpu") and "no GPU device" in why
    monkeypatch.setenv(registry.BACKEND_VARIABLE, "reference")
    assert registry.backend_renderer("auto") == ("reference", "cpu", "QUILTING_BACKEND=reference")


# --------------------------------------------------------------------------------------------
# get_backend
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "cls"), [("fft", FFTBackend), ("reference", ReferenceBackend)])
def test_get_backend_by_name(name: str, cls: type, fake_gl: type[FakeGL]) -> None:
    backend = registry.get_backend(name)
    assert type(backend) is cls and backend.name == name and backend.renderer == "cpu"
    assert isinstance(backend, CostBackend)


def test_get_gl_by_name_has_no_safety_net(fake_gl: type[FakeGL]) -> None:
    backend = registry.get_backend("gl")
    assert isinstance(backend, FakeGLBackend)
    fake_gl.start_error = "the GPU is gone"
    with pytest.raises(BackendError, match="the GPU is gone"):
        registry.get_backend("gl")


def test_get_gl_without_moderngl_says_which_extra(no_moderngl: None) -> None:
    with pytest.raises(BackendError, match=r"needs moderngl \(pip install 'quilting\[gl\]'\)"):
        registry.get_backend("gl")


def test_get_auto_without_a_gpu_is_plain_fft(fake_gl: type[FakeGL]) -> None:
    fake_gl.nodes = []
    assert type(registry.get_backend("auto")) is FFTBackend


def test_get_auto_on_a_gpu_is_gl_with_a_safety_net(fake_gl: type[FakeGL]) -> None:
    backend = registry.get_backend("auto")
    assert isinstance(backend, FallbackBackend)
    assert backend.name == "gl" and backend.renderer == "Fake GPU 9000"
    assert backend.fallback is None


def test_get_auto_falls_back_to_fft_when_the_gpu_cannot_start(fake_gl: type[FakeGL]) -> None:
    fake_gl.start_error = "out of device memory"
    backend = registry.get_backend("auto")
    assert isinstance(backend, FallbackBackend)
    assert backend.name == "fft" and backend.renderer == "cpu"
    assert backend.fallback == "the GPU backend failed to start: out of device memory"


@pytest.mark.parametrize("forced", ["gl", "reference"])
def test_the_variable_counts_as_asking_by_name(
    forced: str, fake_gl: type[FakeGL], monkeypatch: pytest.MonkeyPatch
) -> None:
    # QUILTING_BACKEND=gl is the operator's explicit choice: no silent fallback.
    monkeypatch.setenv(registry.BACKEND_VARIABLE, forced)
    backend = registry.get_backend("auto")
    assert not isinstance(backend, FallbackBackend) and backend.name == forced
    if forced == "gl":
        fake_gl.start_error = "the GPU is gone"
        with pytest.raises(BackendError, match="the GPU is gone"):
            registry.get_backend("auto")


# --------------------------------------------------------------------------------------------
# FallbackBackend, with scripted fake backends
# --------------------------------------------------------------------------------------------


@dataclass
class Scripted:
    """A backend that records its calls and raises on the calls it is told to fail."""

    name: str
    renderer: str = "fake"
    #: Call numbers (1-based, over prepare/fields/shortlists together) that raise.
    fail_on: set[int] = field(default_factory=set)
    error: type[Exception] = BackendError
    close_error: bool = False
    calls: list[tuple[str, Any]] = field(default_factory=list)

    def _step(self, what: str, payload: Any) -> None:
        self.calls.append((what, payload))
        if sum(c[0] != "close" for c in self.calls) in self.fail_on:
            raise self.error(f"{self.name} broke on {what}")

    def prepare(
        self, source: NDArray[np.float32], block: int, guide: NDArray[np.float32] | None = None
    ) -> None:
        self._step("prepare", (source, block, guide))

    def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
        self._step("fields", requests)
        return FieldBatch(np.full((len(requests), 1, 1), len(self.calls)), np.zeros(len(requests)))

    def shortlists(
        self, requests: Sequence[CostRequest], tolerance: float, min_candidates: int
    ) -> list[Shortlist]:
        self._step("shortlists", (requests, tolerance, min_candidates))
        return [Shortlist(np.zeros(1, np.intp), np.zeros(1), 0.0) for _ in requests]

    def close(self) -> None:
        self.calls.append(("close", None))
        if self.close_error:
            raise BackendError(f"{self.name} could not close")

    def made(self) -> Callable[[], Scripted]:
        return lambda: self


def never() -> CostBackend:
    raise AssertionError("the secondary was made although the primary never failed")


SOURCE = np.zeros((8, 8, 3), dtype=np.float32)
GUIDE = np.zeros((8, 8, 1), dtype=np.float32)
REQUESTS = [CostRequest(np.zeros((4, 4, 3), np.float32), np.ones((4, 4), np.float32))]


def test_a_working_primary_does_everything(monkeypatch: pytest.MonkeyPatch) -> None:
    gpu = Scripted("gpu", renderer="Fake GPU")
    backend = FallbackBackend(gpu.made(), never)
    assert isinstance(backend, CostBackend)
    assert (backend.name, backend.renderer, backend.fallback) == ("gpu", "Fake GPU", None)
    backend.prepare(SOURCE, 4, GUIDE)
    assert backend.fields(REQUESTS).values.shape == (1, 1, 1)
    assert len(backend.shortlists(REQUESTS, 0.1, 3)) == 1
    backend.close()
    assert [c[0] for c in gpu.calls] == ["prepare", "fields", "shortlists", "close"]
    # Arguments are passed through untouched.
    assert gpu.calls[0][1][0] is SOURCE and gpu.calls[0][1][1:] == (4, GUIDE)
    assert gpu.calls[2][1] == (REQUESTS, 0.1, 3)


def test_a_primary_that_cannot_start_is_replaced_at_once() -> None:
    cpu = Scripted("cpu", renderer="cpu")

    def broken() -> CostBackend:
        raise BackendError("no context")

    backend = FallbackBackend(broken, cpu.made())
    assert (backend.name, backend.renderer) == ("cpu", "cpu")
    assert backend.fallback == "the GPU backend failed to start: no context"
    backend.prepare(SOURCE, 4)
    assert [c[0] for c in cpu.calls] == ["prepare"]


def test_other_errors_at_start_are_not_swallowed() -> None:
    # Only a BackendError means "the GPU failed"; a bug must surface, not hide behind fft.
    def buggy() -> CostBackend:
        raise TypeError("a bug")

    with pytest.raises(TypeError, match="a bug"):
        FallbackBackend(buggy, never)


@pytest.mark.parametrize("failing", ["fields", "shortlists"])
def test_a_mid_job_failure_moves_the_job_to_the_secondary(failing: str) -> None:
    gpu = Scripted("gpu", fail_on={3}, close_error=True)  # prepare, fields ok; the 3rd fails
    cpu = Scripted("cpu", renderer="cpu")
    backend = FallbackBackend(gpu.made(), cpu.made())
    backend.prepare(SOURCE, 4, GUIDE)
    backend.fields(REQUESTS)
    call = getattr(backend, failing)
    args = (REQUESTS,) if failing == "fields" else (REQUESTS, 0.2, 5)
    result = call(*args)
    # The failed call was answered by the secondary, prepared with the same job first.
    assert [c[0] for c in cpu.calls] == ["prepare", failing]
    prepared = cpu.calls[0][1]
    assert prepared[0] is SOURCE and prepared[1] == 4 and prepared[2] is GUIDE
    assert result is not None
    # The primary was closed (its close failing too is no reason to stop) and left for good.
    assert gpu.calls[-1][0] == "close"
    assert backend.fallback == f"gpu failed: gpu broke on {failing}"
    assert (backend.name, backend.renderer) == ("cpu", "cpu")
    gpu_calls = len(gpu.calls)
    backend.fields(REQUESTS)
    backend.shortlists(REQUESTS, 0.1, 3)
    assert len(gpu.calls) == gpu_calls
    assert [c[0] for c in cpu.calls][-2:] == ["fields", "shortlists"]


def test_a_failure_in_prepare_prepares_the_secondary_once() -> None:
    # The switch prepares the secondary with the job; the docstring of prepare says nothing
    # is then left to do, so the job (spectra, uploads: the costly per-job work) must not be
    # prepared a second time.
    gpu = Scripted("gpu", fail_on={1})
    cpu = Scripted("cpu")
    backend = FallbackBackend(gpu.made(), cpu.made())
    backend.prepare(SOURCE, 4)
    assert backend.fallback == "gpu failed: gpu broke on prepare"
    assert [c[0] for c in cpu.calls] == ["prepare"]


def test_a_failure_before_any_job_needs_no_prepare() -> None:
    gpu = Scripted("gpu", fail_on={1})
    cpu = Scripted("cpu")
    backend = FallbackBackend(gpu.made(), cpu.made())
    backend.fields(REQUESTS)
    assert [c[0] for c in cpu.calls] == ["fields"]


def test_after_close_a_failure_does_not_replay_the_old_job() -> None:
    gpu = Scripted("gpu", fail_on={2})
    cpu = Scripted("cpu")
    backend = FallbackBackend(gpu.made(), cpu.made())
    backend.prepare(SOURCE, 4)
    backend.close()
    backend.fields(REQUESTS)
    assert [c[0] for c in cpu.calls] == ["fields"]


def test_there_is_one_fallback_only() -> None:
    gpu = Scripted("gpu", fail_on={2})
    cpu = Scripted("cpu", fail_on={3})  # prepare (replayed), fields ok, then fails
    backend = FallbackBackend(gpu.made(), cpu.made())
    backend.prepare(SOURCE, 4)
    backend.fields(REQUESTS)
    first = backend.fallback
    with pytest.raises(BackendError, match="cpu broke on fields"):
        backend.fields(REQUESTS)
    assert backend.fallback == first  # the reason for the one switch is kept
    assert gpu.calls[-1][0] == "close" and len(gpu.calls) == 3  # prepare, fields, close


def test_other_errors_mid_job_are_not_a_fallback() -> None:
    gpu = Scripted("gpu", fail_on={2}, error=ValueError)
    backend = FallbackBackend(gpu.made(), never)
    backend.prepare(SOURCE, 4)
    with pytest.raises(ValueError, match="gpu broke on fields"):
        backend.fields(REQUESTS)
    assert backend.fallback is None and backend.name == "gpu"


def test_a_switch_mid_job_gives_the_secondary_s_own_fields() -> None:
    # End to end with real backends: reference as the "GPU" failing on its second batch,
    # fft as the secondary. After the switch the fields are fft's for the same job: the
    # replayed prepare had the right source, block and guide.
    rng = np.random.default_rng(3)
    source = rng.random((20, 22, 3), dtype=np.float32)
    guide = rng.random((20, 22, 1), dtype=np.float32)
    requests = [
        CostRequest(
            rng.random((6, 6, 3), dtype=np.float32),
            (rng.random((6, 6)) < 0.5).astype(np.float32),
            guide=rng.random((6, 6, 1), dtype=np.float32),
            guide_weight=0.7,
        )
        for _ in range(3)
    ]

    class FlakyReference(ReferenceBackend):
        batches = 0

        def fields(self, requests: Sequence[CostRequest]) -> FieldBatch:
            FlakyReference.batches += 1
            if FlakyReference.batches == 2:
                raise BackendError("the GPU went away (test)")
            return super().fields(requests)

    backend = FallbackBackend(FlakyReference, lambda: FFTBackend(threads=1))
    backend.prepare(source, 6, guide)
    first = backend.fields(requests)
    second = backend.fields(requests)
    assert backend.name == "fft" and backend.fallback is not None
    alone = FFTBackend(threads=1)
    alone.prepare(source, 6, guide)
    want = alone.fields(requests)
    np.testing.assert_array_equal(second.values, want.values)
    # And both agree with the exact fields within the bound the fft reports.
    gap = np.abs(second.values - first.values).max(axis=(1, 2))
    assert np.all(gap <= second.error_bound)
