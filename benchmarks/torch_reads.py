"""What torch's attribute reads of a one-pose call cost in cold caches, and the single calls that could replace them.

A torch pose's one-pose call (:mod:`nik.ik.backends.one_pose`) reads six attributes of the pose (dtype, ``is_cpu``,
shape, ``is_contiguous()``, ``is_neg()``, ``data_ptr()``) and five of its output slot (the storage's use count,
``_version``, ``requires_grad``, two ``grad``). This times each read alone, the groups, and the ways of getting the
pose's layout from one call: ``torch._C._to_dlpack`` (a capsule), ``Tensor.type()``, and the DLTensor of the DLPack
exchange API (``torch._C._dlpack_exchange_api``: ``dltensor_from_py_object_no_sync`` called from a numba function
with the GIL held, which also copies the 16 numbers; beside it ``pose at address``, the six reads and a numba copy of
the 16 numbers at ``data_ptr()`` as the shipped path does). Blocks of ``--block`` calls of one way (blocks in a seeded
random order, the first two of each block not counted), ``--idle`` seconds asleep before each call (0.5 ms: the
caches cold, as after a control loop's other work), on 300 float64 ``(4, 4)`` tensors; medians over calls, then the
median over ``--rounds`` and its range of the difference to ``nothing`` (the call of a function that reads nothing).

    python benchmarks/torch_reads.py --rounds 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
import torch

USES = torch._C._storage_Use_Count
_BASE = torch.from_numpy(np.empty(64, dtype=np.uint8))  # an output slot's tensors, as one_pose._Outs makes them
Q, OK = _BASE[:48].view(torch.float64).view(1, 6), _BASE[56:57].view(torch.bool)
CD = _BASE.untyped_storage()._cdata
OUT = np.empty((1, 4, 4))


def _six(t):
    t.dtype, t.is_cpu, t.shape  # noqa: B018
    return t.is_contiguous() and not t.is_neg() and t.data_ptr()


def _slot(t):
    return USES(CD), Q._version == 0 and not Q.requires_grad and Q.grad is None and OK.grad is None


WAYS = {
    "nothing": lambda t: None,
    "dtype": lambda t: t.dtype,
    "is_cpu": lambda t: t.is_cpu,
    "shape": lambda t: t.shape,
    "is_contiguous()": lambda t: t.is_contiguous(),
    "is_neg()": lambda t: t.is_neg(),
    "data_ptr()": lambda t: t.data_ptr(),
    "the six pose reads": _six,
    "slot: storage uses": lambda t: USES(CD),
    "slot: _version": lambda t: Q._version,
    "slot: requires_grad": lambda t: Q.requires_grad,
    "slot: two grad": lambda t: Q.grad is None and OK.grad is None,
    "slot: the five reads": _slot,
    "six + slot's five": lambda t: (_six(t), _slot(t)),
    "_to_dlpack (capsule)": lambda t: id(torch._C._to_dlpack(t)),
    "Tensor.type()": lambda t: t.type(),
}


def _exchange_ways():
    """The DLPack exchange API's DLTensor read in a numba function (GIL held), beside the shipped read at
    ``data_ptr()``; {} where torch has no exchange API."""
    if not hasattr(torch._C, "_dlpack_exchange_api"):
        return {}
    import ctypes

    import numba
    from llvmlite import ir
    from numba import carray, types
    from numba.core import cgutils
    from numba.extending import intrinsic

    get = ctypes.pythonapi.PyCapsule_GetPointer
    get.restype, get.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    api = get(torch._C._dlpack_exchange_api(), b"dlpack_exchange_api")
    fn = ctypes.c_void_p.from_address(api + 40).value  # header (16 bytes), three pointers, then this one

    @intrinsic
    def _dltensor(typingctx, f, obj):
        ret = types.UniTuple(types.int64, 7)

        def codegen(context, builder, sig, args):
            i64, i8p = ir.IntType(64), ir.IntType(8).as_pointer()
            buf = cgutils.alloca_once(builder, ir.ArrayType(i64, 6))
            call = builder.inttoptr(args[0], ir.FunctionType(ir.IntType(32), [i8p, i8p]).as_pointer())
            rc = builder.call(call, [builder.inttoptr(args[1], i8p), builder.bitcast(buf, i8p)])
            zero = ir.Constant(ir.IntType(32), 0)
            vals = [builder.load(builder.gep(buf, [zero, ir.Constant(ir.IntType(32), k)])) for k in range(6)]
            return context.make_tuple(builder, ret, [builder.sext(rc, i64), *vals])

        return ret(f, obj), codegen

    @intrinsic
    def _at(typingctx, address):
        def codegen(context, builder, sig, args):
            return builder.inttoptr(args[0], context.get_value_type(sig.return_type))

        return types.CPointer(types.float64)(address), codegen

    @numba.njit
    def read(f, obj, T):
        rc, data, device, ndim_dtype, shape, strides, offset = _dltensor(f, obj)
        if rc != 0 or device & 0xFFFFFFFF != 1 or ndim_dtype >> 32 != (2 | 64 << 8 | 1 << 16):
            return False
        P = carray(_at(data + offset), (4, 4))
        for r in range(4):
            for c in range(4):
                T[0, r, c] = P[r, c]
        return True

    @numba.njit(nogil=True)
    def at(address, T):
        P = carray(_at(address), (4, 4))
        for r in range(4):
            for c in range(4):
                T[0, r, c] = P[r, c]
        return True

    return {
        "pose at address (shipped)": lambda t: _six(t) and at(t.data_ptr(), OUT),
        "is_neg() + exchange DLTensor": lambda t: not t.is_neg() and read(fn, id(t), OUT),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--block", type=int, default=10)
    p.add_argument("--idle", type=float, default=0.0005, help="seconds asleep before each call (0: call after call)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    ways = {**WAYS, **_exchange_ways()}
    poses = list(torch.eye(4, dtype=torch.float64).repeat(300, 1, 1))
    for f in ways.values():  # compiled and warm
        f(poses[0])
    labels, rng = list(ways), np.random.default_rng(0)
    per = {k: [] for k in labels}
    for _ in range(args.rounds):
        times = {k: [] for k in labels}
        for i0 in range(0, len(poses), args.block):
            for x in rng.permutation(len(labels)):
                f = ways[labels[x]]
                for i in range(i0, i0 + args.block):
                    if args.idle:
                        time.sleep(args.idle)
                    t0 = time.perf_counter_ns()
                    f(poses[i])
                    dt = (time.perf_counter_ns() - t0) / 1e3
                    if i - i0 >= 2:
                        times[labels[x]].append(dt)
        for k in labels:
            per[k].append(statistics.median(times[k]))
    print(f"torch {torch.__version__}, idle {args.idle * 1e3:g} ms, {args.rounds} rounds, blocks of {args.block}")
    print("| way | us | minus nothing [range] |\n|---|---|---|")
    for k in labels:
        d = [a - b for a, b in zip(per[k], per["nothing"], strict=True)]
        print(f"| {k} | {statistics.median(per[k]):.2f} | {statistics.median(d):+.2f} [{min(d):+.2f}, {max(d):+.2f}] |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
