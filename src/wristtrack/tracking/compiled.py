"""The compiled tracker step: tracking/kernel.py compiled by numba, with its constants.

The Tracker runs it for the default configuration where it loads, and the generic path (the
reference) for everything else and for every frame the step declines (see kernel.py).

``load`` imports numba and compiles the step on first use (importing wristtrack does not import
numba). The compiled code is cached on disk (numba ``cache=True``: ``__pycache__`` beside this
file, or numba's user-wide cache directory when the package folder is not writable), so one
process per machine pays the compile (~15 s of CPU) and later ones load it (~1 s). The cache
key includes a digest of the code of every function compiled into the step, so editing a
helper in geometry.py, depth_noise.py or kernel.py compiles the step afresh rather than load a
stale one. Where numba cannot be imported or cannot compile, ``load`` returns None and
``describe`` says why; the generic path then takes every frame.
"""

from __future__ import annotations

import hashlib
import math
import threading
import types
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from wristtrack.filter import associate as assoc
from wristtrack.filter import ukf
from wristtrack.tracking import kernel, merged
from wristtrack.tracking.kernel import (
    _CX,
    _CY,
    _DEPTH_COEFF,
    _DEPTH_DELAY,
    _DEPTH_FLOOR,
    _DEPTH_OBLIQUE,
    _DEPTH_OFFSET,
    _DEPTH_Z0,
    _DIST,
    _DISTORTED,
    _FACING_COS,
    _FX,
    _FY,
    _GATE_CONSTANT,
    _GRAZING_COS,
    _HALF_GATE,
    _MERGE_REACH,
    _N_OFFSET,
    _N_PAR,
    _OFFSET_GRAZING_COS,
    _PIXEL_VAR,
    _READOUT,
    _REGISTRATION_PX,
    _SCALE,
    _SLIDE_TAU,
    _SLIDE_VAR,
    _SQRT_DRIFT,
    _SQRT_QA,
    _SQRT_QW,
    _U_MAX,
    _V_MAX,
    DECLINED,
    OK,
)
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.observation import GRAZING_COS, OFFSET_GRAZING_COS, STATE_SLIDE_AXES
from wristtrack.tracking.offset_model import DepthOffsetModel
from wristtrack.tracking.slide_model import SlidingSkinModel

if TYPE_CHECKING:
    from wristtrack.tracking.observation import MarkerObservation

__all__ = ["DECLINED", "MODELS", "OK", "describe", "frame_constants", "load", "set_depth_delay"]

# The state models the step carries (exactly these: a subclass may change what they compute)
MODELS = (ConstantRateModel, SlidingSkinModel, DepthOffsetModel)


def set_depth_delay(constants: tuple, delay: float) -> None:
    """The depth of the next frames read ``delay`` s after the colour
    (MarkerObservation.depth_delay), in ``frame_constants``' result."""
    constants[-1][_DEPTH_DELAY] = delay


def frame_constants(
    model: ConstantRateModel,
    obs: MarkerObservation,
    ukf_params: ukf.UKFParams,
    facing_cos: float,
    assoc_params: assoc.AssociationParams,
    merged_blobs: bool = True,
) -> tuple:
    """The step's arguments after (x, P, dt, uv, depth, blob_var) for one tracker (fixed W0 and
    layout): layout (J, 3), its skin slide taken as noise (J, 3), the markers the state's slide
    moves (J,) (none without a SlidingSkinModel), R_c0, t_c0, the unscented weights and the
    scalar constants ``par``. ``merged_blobs``: TrackerConfig.merged_blobs (the step leaves frames
    where blobs may have merged to the generic path)."""
    n = model.dim + model.noise_dim
    w = ukf.sigma_weights(n, ukf_params.alpha, ukf_params.beta, ukf_params.kappa)
    gate_constant, half_gate = assoc.full_measurement_constants(assoc_params)
    camera, noise, process = obs.camera, obs.noise, model.noise
    par = np.empty(_N_PAR)
    par[_SCALE] = w.scale
    par[_FX], par[_FY], par[_CX], par[_CY] = camera.fx, camera.fy, camera.cx, camera.cy
    par[_U_MAX], par[_V_MAX] = camera.width - 0.5, camera.height - 0.5
    par[_PIXEL_VAR] = noise.pixel_sigma**2
    par[_DEPTH_COEFF], par[_DEPTH_FLOOR] = noise.depth_coeff, noise.depth_floor
    par[_DEPTH_OFFSET], par[_DEPTH_Z0] = noise.depth_offset, noise.depth_z0
    par[_DEPTH_OBLIQUE] = noise.depth_oblique
    par[_SQRT_QA] = math.sqrt(process.linear_accel)
    par[_SQRT_QW] = math.sqrt(process.angular_accel)
    par[_FACING_COS] = facing_cos
    par[_GATE_CONSTANT], par[_HALF_GATE] = gate_constant, half_gate
    par[_REGISTRATION_PX], par[_GRAZING_COS] = noise.registration_px, GRAZING_COS
    par[_OFFSET_GRAZING_COS] = OFFSET_GRAZING_COS
    par[_DEPTH_DELAY] = obs.depth_delay
    par[_READOUT] = obs.readout
    par[_MERGE_REACH] = merged.merge_reach(camera.fx) if merged_blobs else 0.0
    sliding = np.zeros(obs.n_markers)
    par[_DISTORTED] = float(camera.has_distortion)
    par[_DIST:_DIST + 8] = camera.distortion_terms()
    par[_SLIDE_TAU], par[_SLIDE_VAR:_SLIDE_VAR + 3] = 1.0, 0.0
    if isinstance(model, SlidingSkinModel):  # its slide_scale too is learned: made again then
        # the step moves the markers along the hand's first axes, in order
        assert STATE_SLIDE_AXES == tuple(range(len(STATE_SLIDE_AXES)))
        sliding[obs.sliding] = 1.0
        par[_SLIDE_TAU] = model.time_constant
        par[_SLIDE_VAR:_SLIDE_VAR + len(STATE_SLIDE_AXES)] = model.stationary_variance
    par[_N_OFFSET], par[_SQRT_DRIFT] = 0.0, 0.0
    if isinstance(model, DepthOffsetModel):  # (du, dv) after the slide
        par[_N_OFFSET], par[_SQRT_DRIFT] = 2.0, math.sqrt(model.drift)
    # C-contiguous, writable float64: the types the step is compiled for (see _warm_up_arguments).
    # The tracker makes these again whenever the noise it learns changes (tracking/noise_scale.py)
    layout, slide = np.ascontiguousarray(obs.layout_T.T), np.ascontiguousarray(obs.slide)
    R_c0, t_c0 = np.ascontiguousarray(obs.R_c0), np.ascontiguousarray(obs.t_c0)
    return layout, slide, sliding, R_c0, t_c0, w.mean.copy(), w.cov.copy(), par


# ----------------------------------------------------------------------------- loading

_loaded: tuple[Callable | None, str] | None = None  # (the compiled step or None, description)
_loading = threading.Lock()  # one compile per process, even with trackers in several threads
# the step's helpers as Python functions, before _jit rebinds their names in kernel
_PYTHON_HELPERS = {name: getattr(kernel, name) for name in kernel.HELPERS}


def load() -> Callable | None:
    """The compiled step, or None where numba cannot be imported or cannot compile it (the
    tracker then takes the generic path). The first call in a process imports numba and
    compiles the step or loads it from the on-disk cache; later calls return it at once."""
    global _loaded
    with _loading:
        if _loaded is None:
            _loaded = _compile()
    return _loaded[0]


def describe() -> str:
    """Which step the tracker runs, for ``wristtrack --version``: "compiled (numba 0.61.0)" or
    "generic NumPy reference (numba not available: <reason>)". Loads the step (see ``load``)."""
    load()
    return _loaded[1]


def _compile() -> tuple[Callable | None, str]:
    try:
        import numba
    except Exception as err:  # ImportError, or a numba built for another NumPy failing to load
        return None, f"generic NumPy reference (numba not available: {_first_line(err)})"
    version = numba.__version__
    try:
        step = _jit(numba)
        step(*_warm_up_arguments())  # compile now (or load the cache), not in the first frame
    except Exception as err:  # a numba that cannot compile this code: the generic path works
        reason = f"numba {version} could not compile the step: {_first_line(err)}"
        return None, f"generic NumPy reference ({reason})"
    return step, f"compiled (numba {version})"


def _jit(numba) -> Callable:
    """Compile kernel.step's helpers under the names it calls them by, then the step.

    No fastmath: the results must equal the generic path's to rounding, and the NaN tests must
    work. numpy's error model: a division by zero gives inf or NaN as in NumPy (which the checks
    then catch) instead of raising. Only the outermost function is cached (its object code holds
    everything it calls), and numba keys its cache on that function's file and closure only:
    hence the closure over a digest of all the code compiled into it.
    """
    names = vars(kernel)
    functions = [*_PYTHON_HELPERS.values(), kernel.step]
    for name, function in _PYTHON_HELPERS.items():
        names[name] = numba.njit(nogil=True, error_model="numpy")(function)
    global _kernel_step
    _kernel_step = numba.njit(nogil=True, error_model="numpy")(kernel.step)
    digest = _code_digest(functions)

    def step(x, P, dt, uv, depth, blob_var, layout, slide, sliding, R_c0, t_c0, wm, wc, par):
        if digest < 0:  # never: the digest is there to be part of the cache key
            return _kernel_step(x, P, -dt, uv, depth, blob_var, layout, slide, sliding, R_c0,
                                t_c0, wm, wc, par)
        return _kernel_step(x, P, dt, uv, depth, blob_var, layout, slide, sliding, R_c0, t_c0,
                            wm, wc, par)

    try:
        return numba.njit(cache=True, nogil=True, error_model="numpy")(step)
    except RuntimeError:  # no writable cache directory anywhere: compile in every process
        return numba.njit(nogil=True, error_model="numpy")(step)


_kernel_step = kernel.step  # the compiled kernel.step once _jit has run


def _code_digest(functions: Iterable[types.FunctionType]) -> int:
    """A 56-bit digest of the functions' byte code, names and constants (nested code too)."""
    h = hashlib.sha256()

    def add(code: types.CodeType) -> None:
        h.update(code.co_code)
        h.update(repr(code.co_names).encode())
        for c in code.co_consts:
            if isinstance(c, types.CodeType):
                add(c)
            else:
                h.update(repr(c).encode())

    for f in functions:
        add(f.__code__)
    return int.from_bytes(h.digest()[:7], "little")


def _warm_up_arguments() -> tuple:
    """Arguments of the types the tracker passes (C-contiguous writable float64 arrays, a float
    dt), so the compile done here is the one every frame uses. The values do not matter."""
    x = np.concatenate((np.eye(3).reshape(9), np.zeros(9)))
    par = np.ones(_N_PAR)
    par[_N_OFFSET] = 0.0  # the 12 states of x: no offset
    return (x, np.eye(12), 0.03, np.zeros((1, 2)), np.ones(1), np.zeros(1), np.zeros((6, 3)),
            np.zeros((6, 3)), np.zeros(6), np.eye(3), np.ones(3), np.ones(37), np.ones(37),
            par)  # fmt: skip


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


