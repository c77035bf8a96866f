"""numpy's numbers inside numba kernels, bit for bit: shared by the world's and the agents' kernels.

The e-puck world (``world/epuck/kernels.py``) and the e-puck brain (``agents/epuck/kernels.py``)
run compiled kernels that must give numpy's results to the last bit (``benchmarks/fingerprint.py``).
What they need of numpy is here, once, in the root package (no Zenoh, no world, no agent):

- random draws: :func:`generator_address` gives the ``next_double`` function of a
  ``numpy.random.Generator``'s bit generator and its state, and :func:`call_next_double` calls it
  from a kernel: the very function ``Generator.random`` calls for each number, so the stream is
  numpy's and the generator's state advances as if numpy had drawn;
- ``exp`` and ``arctan2``: numpy evaluates them with its own SIMD routines on this hardware,
  which differ from the C library's in the last bit; :func:`np_exp` and :func:`np_arctan2` call
  those very routines (:func:`numpy_math` finds them and checks them against numpy once per
  process), else the C library's if it agrees with numpy here, else numpy itself from the kernel.

numba kernels of other modules import and call these as they would their own; they are compiled
with ``cache=True`` like the rest. ``tests/test_batch_kernels.py`` holds them to numpy.
"""

from __future__ import annotations

import ctypes
import functools
import importlib
import math

import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit, objmode, types
from numba.extending import intrinsic

#: How kernels get numpy's float64 ``exp`` and ``arctan2`` bit for bit (:func:`numpy_math`):
#: numpy's own SIMD routines (SVML, on x86-64 with AVX-512), the C library's, or numpy itself.
MATH_SVML, MATH_LIBM, MATH_NUMPY = 0, 1, 2
#: Slots of the ``math_fns`` array of :func:`numpy_math`: the mode, then the SVML entry points,
#: then the addresses of a strategy's own fusion rule (e-puck, ``agents/epuck/fusion.py``: its
#: gain and its confidence after a fusion; 0 when the strategy uses a built-in rule). The array
#: is what every compiled kernel already receives, so a pointer a kernel calls travels with it.
M_MODE, M_EXP, M_ATAN2, M_GAIN, M_CONFIDENCE = 0, 1, 2, 3, 4
N_MATH_FNS = 5


def generator_address(rng: np.random.Generator) -> tuple[int, int]:
    """``(next_double, state)`` addresses of a generator's bit generator, for kernels that draw
    from it: the function ``Generator.random`` calls for each number, so they draw the same
    stream and advance the generator as numpy would (numba's own ``Generator`` support does the
    same but unboxes the generator for some 7 us per call). Valid while ``rng`` lives; not for
    use from two threads at once (numpy's own calls take the bit generator's lock; kernels do
    not)."""
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    c = rng.bit_generator.ctypes
    return ctypes.cast(c.next_double, ctypes.c_void_p).value, int(c.state_address)


@intrinsic
def call_next_double(typingctx, fn_address, state_address):
    """``next_double(state)`` of a numpy bit generator (addresses of :func:`generator_address`)."""
    sig = types.float64(types.intp, types.intp)

    def codegen(context, builder, signature, args):
        byte_ptr = llvm_ir.IntType(8).as_pointer()
        fn = builder.inttoptr(args[0], llvm_ir.FunctionType(llvm_ir.DoubleType(), [byte_ptr]).as_pointer())
        return builder.call(fn, [builder.inttoptr(args[1], byte_ptr)])

    return sig, codegen


@intrinsic
def call_f64_3(typingctx, fn_address, a, b, c):
    """``f(a, b, c)`` of a C function ``double f(double, double, double)`` at ``fn_address``
    (a numba ``cfunc``'s ``address``)."""
    sig = types.float64(types.intp, types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = llvm_ir.DoubleType()
        fn = builder.inttoptr(args[0], llvm_ir.FunctionType(d, [d, d, d]).as_pointer())
        return builder.call(fn, list(args[1:]))

    return sig, codegen


@intrinsic
def call_f64_4(typingctx, fn_address, a, b, c, e):
    """``f(a, b, c, e)`` of a C function ``double f(double, double, double, double)`` at
    ``fn_address``."""
    sig = types.float64(types.intp, types.float64, types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = llvm_ir.DoubleType()
        fn = builder.inttoptr(args[0], llvm_ir.FunctionType(d, [d, d, d, d]).as_pointer())
        return builder.call(fn, list(args[1:]))

    return sig, codegen


_F64X8 = llvm_ir.VectorType(llvm_ir.DoubleType(), 8)


@intrinsic
def _svml_exp_lane0(typingctx, fn_address, x):
    """numpy's SVML ``exp`` (one ``__m512d`` in, one out) of ``x`` in lane 0, zeros elsewhere:
    how numpy evaluates a lone element."""
    sig = types.float64(types.intp, types.float64)

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], llvm_ir.FunctionType(_F64X8, [_F64X8]).as_pointer())
        lane0 = llvm_ir.Constant(llvm_ir.IntType(32), 0)
        v = builder.insert_element(llvm_ir.Constant(_F64X8, [0.0] * 8), args[1], lane0)
        return builder.extract_element(builder.call(fn, [v]), lane0)

    return sig, codegen


@intrinsic
def _svml_atan2_x8(typingctx, fn_address, y_address, x_address, out_address):
    """numpy's SVML ``atan2`` of 8 consecutive float64 at ``y_address``, ``x_address``, to
    ``out_address``."""
    sig = types.void(types.intp, types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], llvm_ir.FunctionType(_F64X8, [_F64X8, _F64X8]).as_pointer())
        ptr = _F64X8.as_pointer()
        y = builder.load(builder.inttoptr(args[1], ptr), align=8)
        x = builder.load(builder.inttoptr(args[2], ptr), align=8)
        builder.store(builder.call(fn, [y, x]), builder.inttoptr(args[3], ptr), align=8)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, error_model="numpy")
def np_exp(x, math_fns):
    """numpy's ``exp`` of one float64, bit for bit (``math_fns`` of :func:`numpy_math`)."""
    mode = math_fns[M_MODE]
    if mode == MATH_SVML:
        return _svml_exp_lane0(math_fns[M_EXP], x)
    if mode == MATH_LIBM:
        return math.exp(x)
    with objmode(out="float64"):
        out = float(np.exp(np.array([x]))[0])
    return out


@njit(cache=True, error_model="numpy")
def np_arctan2(y, x, out, math_fns):
    """``out[:] = numpy.arctan2(y, x)`` bit for bit, for 1-D float64 arrays of one length (numpy's
    SIMD loop runs 8 lanes at a time and pads the last vector with zeros: so does this)."""
    n = y.shape[0]
    mode = math_fns[M_MODE]
    if mode == MATH_SVML:
        if y.strides[0] == 8 and x.strides[0] == 8 and out.strides[0] == 8:
            _svml_atan2_run(math_fns[M_ATAN2], y.ctypes.data, x.ctypes.data, out.ctypes.data, n)
        else:
            yc, xc, oc = np.ascontiguousarray(y), np.ascontiguousarray(x), np.empty(n)
            _svml_atan2_run(math_fns[M_ATAN2], yc.ctypes.data, xc.ctypes.data, oc.ctypes.data, n)
            out[:] = oc
    elif mode == MATH_LIBM:
        for q in range(n):
            out[q] = math.atan2(y[q], x[q])
    else:
        with objmode():
            np.arctan2(y, x, out=out)


@njit(cache=True, error_model="numpy")
def _svml_atan2_run(fn, y_address, x_address, out_address, n):
    """SVML ``atan2`` of ``n`` contiguous float64, 8 at a time, the last vector zero-padded."""
    q = 0
    while q + 8 <= n:
        _svml_atan2_x8(fn, y_address + 8 * q, x_address + 8 * q, out_address + 8 * q)
        q += 8
    if q < n:
        tail = np.zeros(24)
        t = tail.ctypes.data
        for k in range(n - q):
            tail[k] = _load_f64(y_address + 8 * (q + k))
            tail[8 + k] = _load_f64(x_address + 8 * (q + k))
        _svml_atan2_x8(fn, t, t + 64, t + 128)
        for k in range(n - q):
            _store_f64(out_address + 8 * (q + k), tail[16 + k])


@intrinsic
def _load_f64(typingctx, address):
    sig = types.float64(types.intp)

    def codegen(context, builder, signature, args):
        return builder.load(builder.inttoptr(args[0], llvm_ir.DoubleType().as_pointer()), align=8)

    return sig, codegen


@intrinsic
def _store_f64(typingctx, address, value):
    sig = types.void(types.intp, types.float64)

    def codegen(context, builder, signature, args):
        builder.store(args[1], builder.inttoptr(args[0], llvm_ir.DoubleType().as_pointer()), align=8)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, error_model="numpy")
def _probe_math(x, y, z, math_fns):
    e = np.empty_like(x)
    for q in range(x.shape[0]):
        e[q] = np_exp(x[q], math_fns)
    a = np.empty_like(y)
    np_arctan2(y, z, a, math_fns)
    return e, a


def _svml_entry_points() -> tuple[int, int] | None:
    """numpy's SVML ``exp`` and ``atan2`` (``__m512d`` in zmm registers), if numpy has them and
    both numpy and numba's code generator may use AVX-512 here."""
    try:
        import llvmlite.binding as llvm
        from numba.core import config

        umath = importlib.import_module("numpy._core._multiarray_umath")
        if not umath.__cpu_features__.get("AVX512_SKX"):
            return None
        if config.CPU_NAME not in (None, "host") or config.CPU_FEATURES is not None:
            return None
        if not llvm.get_host_cpu_features().get("avx512f"):
            return None
        lib = ctypes.CDLL(umath.__file__)
        return (ctypes.cast(lib.__svml_exp8_ha, ctypes.c_void_p).value,
                ctypes.cast(lib.__svml_atan28_ha, ctypes.c_void_p).value)
    except (ImportError, AttributeError, OSError):
        return None


@functools.cache
def _numpy_math() -> tuple[int, int, int]:
    rng = np.random.default_rng(20261122)
    x = np.concatenate([rng.uniform(-500.0, 500.0, 4096), rng.uniform(-3.0, 3.0, 4096),
                        [0.0, -0.0, 1e-300, -1e-300, 1.0, -1.0, 500.0, -500.0]])
    y, z = rng.normal(size=(2, 8195)) * np.repeat([1.0, 1e-3, 1e3], [4096, 2048, 2051])
    y[:4], z[:4] = [0.0, -0.0, 1.0, -1.0], [-0.0, 0.0, 0.0, -0.0]
    expected = (np.exp(x), np.arctan2(y, z))
    candidates = [(MATH_LIBM, 0, 0)]
    svml = _svml_entry_points()
    if svml is not None:
        candidates.insert(0, (MATH_SVML, *svml))
    for mode in candidates:
        got = _probe_math(x, y, z, np.array(mode, np.int64))
        if all(np.array_equal(g.view(np.int64), e.view(np.int64)) for g, e in zip(got, expected)):
            return mode
    return (MATH_NUMPY, 0, 0)


def numpy_math() -> np.ndarray:
    """``math_fns`` for :func:`np_exp` and :func:`np_arctan2`: the first of numpy's SVML routines
    (what numpy 2 calls on x86-64 with AVX-512), then the C library's, whose results match numpy's
    on a probe of some 8,000 arguments here; else numpy itself, called from the kernel (about a
    microsecond a call). Probed once per process. ``N_MATH_FNS`` slots; those of a fusion rule
    are 0 (none)."""
    out = np.zeros(N_MATH_FNS, np.int64)
    out[:3] = _numpy_math()
    return out


_PI = math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always", error_model="numpy")
def wrap(angle_rad):
    """``(a + pi) % (2 pi) - pi``: Python/numpy float modulo semantics, as ``wrap_angle``. For
    ``x = a + pi`` in ``(-2 pi, 2 pi)`` the modulo is ``x`` or ``x + 2 pi`` exactly (``fmod``
    returns ``x``; a negative one is moved by the divisor), which skips the call to ``fmod``."""
    x = angle_rad + _PI
    if 0.0 <= x < _TWO_PI:
        return x - _PI  # (-0.0 gives -pi here, +0.0 % 2 pi - pi there: the same)
    if -_TWO_PI < x < 0.0:
        return (x + _TWO_PI) - _PI
    return x % _TWO_PI - _PI
