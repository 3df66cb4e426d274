"""The motor's position term in C, inside MuJoCo's own step (``motor.c``).

:class:`armreach_mujoco.servo.Motors` must add ``offset - k q`` to its rows' reference in
every physics step, between ``mj_step1`` and ``mj_step2``. Done from Python, that is four
calls into MuJoCo per physics step, ten per control step: about 2 µs each time, a quarter
of what the engine itself spends on ar6. ``motor.c`` does the same arithmetic as MuJoCo's
control callback (``mjcb_control``, which ``mj_step`` calls at the point where ``mj_step1``
ends), so a control step becomes one ``mj_step(model, data, substeps)`` call. The motion is
the same to the last bit (``backends/mujoco/tests/test_cmotor.py``).

The callback is compiled once per MuJoCo version with the C compiler on ``PATH`` (``$CC``,
else ``cc``) against the headers the ``mujoco`` package ships, into
``$XDG_CACHE_HOME/armreach/mujoco-motor`` (default under ``~/.cache``), and loaded with
ctypes. Where that cannot be done (no compiler, no headers), or with
``ARMREACH_MUJOCO_MOTOR=python``, the motors run their Python loop: the same motion, slower.
The reason is logged once (``armreach.mujoco``).

``mjcb_control`` is global to the process. The callback is installed only where none is,
and then acts only on the ``MjData`` of a motor marked active around that motor's own
``mj_step`` call; every other ``mj_forward`` or ``mj_step`` passes through it untouched.
If another callback is installed later, the next step raises an :class:`ArmReachError`
before stepping, rather than stepping without the motors.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import weakref
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ArmReachError
from armreach_core.robot.cache_files import cache_dir
from armreach_mujoco.engine import log, mujoco

#: Environment variable: ``python`` runs the motors' Python loop instead of the compiled callback.
MOTOR_ENV = "ARMREACH_MUJOCO_MOTOR"
SOURCE = Path(__file__).with_name("motor.c")
#: Headers whose layout the compiled callback depends on.
HEADERS = ("mjdata.h", "mjmodel.h", "mjtype.h")


class _Slot(ctypes.Structure):
    """``armreach_motor`` of ``motor.c``."""

    _fields_ = [
        ("data", ctypes.c_void_p),
        ("active", ctypes.c_int64),
        ("n", ctypes.c_int64),
        ("qadr", ctypes.c_void_p),
        ("gains", ctypes.c_void_p),
        ("targets", ctypes.c_void_p),
        ("calls", ctypes.c_int64),
    ]


def _include() -> Path:
    return Path(mujoco.__file__).parent / "include"


def _build(again: bool = False) -> Path:
    """The compiled callback's path, compiling it first if this MuJoCo's is not cached (or ``again``)."""
    include = _include()
    digest = hashlib.sha1(SOURCE.read_bytes())
    for header in HEADERS:
        digest.update((include / "mujoco" / header).read_bytes())
    digest.update(f"{mujoco.__version__} {platform.machine()} {platform.system()}".encode())
    out = cache_dir("mujoco-motor") / f"motor-{digest.hexdigest()[:16]}.so"
    if out.is_file() and not again:
        return out
    compiler = shlex.split(os.environ.get("CC", "")) or [shutil.which("cc") or shutil.which("gcc") or ""]
    if not compiler[0]:
        raise OSError("no C compiler found (set CC or put cc on PATH)")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        built = Path(tmp) / out.name
        command = [*compiler, "-O2", "-shared", "-fPIC", "-ffp-contract=off", "-I", str(include)]
        result = subprocess.run(
            [*command, str(SOURCE), "-o", str(built)], capture_output=True, text=True, timeout=120, check=False
        )
        if result.returncode != 0:
            raise OSError(f"{' '.join(command)} failed: {result.stderr.strip()[-500:]}")
        os.replace(built, out)  # atomic: processes building it at once each see a whole file
    return out


@functools.lru_cache(maxsize=1)
def library() -> Any:
    """The loaded callback library, or ``None`` where it cannot be had (the reason is logged)."""
    if os.environ.get(MOTOR_ENV, "").strip().lower() == "python":
        return None
    try:
        path = _build()
        try:
            lib = ctypes.CDLL(str(path))
        except OSError as exc:  # a cached file that does not load (cut short, say): built again, once
            log.info("rebuilding the MuJoCo motor's callback: %s", exc)
            lib = ctypes.CDLL(str(_build(again=True)))
    except (OSError, subprocess.SubprocessError) as exc:
        log.info("MuJoCo's motors run their Python loop (the same motion, slower): %s", exc)
        return None
    lib.armreach_motor_register.argtypes = [ctypes.POINTER(_Slot)]
    lib.armreach_motor_register.restype = ctypes.c_int
    lib.armreach_motor_unregister.argtypes = [ctypes.c_int]
    lib.armreach_motor_unregister.restype = None
    lib.armreach_motor_abi.restype = ctypes.c_int
    if lib.armreach_motor_abi() != ctypes.sizeof(_Slot):
        log.info("MuJoCo's motors run their Python loop: the compiled callback's layout does not match")
        return None
    return lib


def installed() -> bool:
    """Whether the compiled callback is MuJoCo's ``mjcb_control``, installing it where none is."""
    lib = library()
    if lib is None:
        return False
    callback = lib.armreach_motor_control  # the same ctypes object on every access
    current = mujoco.get_mjcb_control()
    if current is None:
        mujoco.set_mjcb_control(callback)
        return True
    return current is callback or _address(current) == _address(callback)


def _address(function: Any) -> int | None:
    """A ctypes function's address (``None`` for a Python callable)."""
    try:
        return ctypes.cast(function, ctypes.c_void_p).value
    except (ctypes.ArgumentError, TypeError):
        return None


def compiled_motors(
    data: Any, qpos: npt.NDArray[np.intp], gains: npt.NDArray[np.float64], targets: npt.NDArray[np.float64]
) -> CompiledMotors | None:
    """Compiled motors for the joints at ``qpos`` of ``data``, or ``None``: no compiled callback
    here, or another control callback was installed first (then the motors run in Python).
    ``gains`` and ``targets`` are read where they are at every physics step: write them in place."""
    lib = library()
    if lib is None or not hasattr(data, "_address"):
        return None
    if not installed():
        _log_once("MuJoCo's motors run their Python loop: another control callback (mjcb_control) is installed")
        return None
    try:
        return CompiledMotors(lib, data, qpos, gains, targets)
    except ArmReachError as exc:
        _log_once(f"MuJoCo's motors run their Python loop: {exc}")
        return None


@functools.cache
def _log_once(message: str) -> None:
    log.info(message)


class CompiledMotors:
    """The motors of one ``MjData``, applied by the compiled callback in ``mj_step``.

    Args:
        data: the ``MjData`` they drive.
        qpos: addresses of the motor joints in ``qpos``, in the order of the motor rows.
        gains, targets: each motor's ``positionGain`` and target (float64, contiguous), which the
            callback reads in every physics step: they must be changed in place.
    """

    def __init__(
        self,
        lib: Any,
        data: Any,
        qpos: npt.NDArray[np.intp],
        gains: npt.NDArray[np.float64],
        targets: npt.NDArray[np.float64],
    ) -> None:
        n = len(qpos)
        for name, array in (("gains", gains), ("targets", targets)):
            if array.dtype != np.float64 or not array.flags.c_contiguous or array.shape != (n,):
                raise ValueError(f"{name} must be {n} contiguous float64 values")
        self.data = data
        self._qadr = np.ascontiguousarray(qpos, dtype=np.int64)
        slot = self._slot = _Slot(
            int(data._address), 0, n, self._qadr.ctypes.data, gains.ctypes.data, targets.ctypes.data, 0
        )
        index = self.index = lib.armreach_motor_register(ctypes.byref(slot))
        if index < 0:
            raise ArmReachError("more MuJoCo envs in one process than the compiled motor serves (4096)")
        # the slot and the arrays it points into, held by the finalizer, live until C has let go of them
        weakref.finalize(self, _release, lib, index, (slot, self._qadr, gains, targets))

    def step(self, model: Any, nstep: int) -> None:
        """``nstep`` physics steps with the motors acting."""
        if not installed():
            raise ArmReachError(
                "another MuJoCo control callback (mujoco.set_mjcb_control) replaced armreach's motor; "
                f"remove it, or set {MOTOR_ENV}=python before importing armreach to run the motor without one"
            )
        slot = self._slot
        slot.active = 1
        try:
            mujoco.mj_step(model, self.data, nstep)
        finally:
            slot.active = 0


def _release(lib: Any, index: int, memory: tuple[Any, ...]) -> None:
    """Take a motor's slot off the callback's list; ``memory`` (its slot and arrays) is freed after."""
    lib.armreach_motor_unregister(index)


__all__ = ["MOTOR_ENV", "CompiledMotors", "compiled_motors", "installed", "library"]
