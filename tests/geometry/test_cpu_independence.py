"""mesh_gen's bytes must not depend on the CPU: the same supports and objects built under
other OpenBLAS kernels (``OPENBLAS_CORETYPE``) and without numpy's AVX-512 loops
(``NPY_DISABLE_CPU_FEATURES``) — the knobs that reproduced the cross-machine difference of
``data/mesh_gen`` — hash the same. Each build runs in a fresh interpreter (both knobs are
read at import time)."""

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow

# supports 27, 47, 90, 95, 106 and tool_002/003 changed bytes under OPENBLAS_CORETYPE before
# the fix; supports.parquet's tip turn changed with numpy's AVX-512 loops off
SCRIPT = r"""
import hashlib
from pathlib import Path
import numpy as np
from skt_lib.config.params_file import load_params
from skt_lib.geometry.build import ObjectTask, SupportTask
from skt_lib.geometry.convex import union
from skt_lib.geometry.objects import sample_object
from skt_lib.geometry.supports import sample_support
from skt_lib.seeding import item_rng
params = load_params(Path("params.yaml")); p, seed = params.mesh_gen, params.common.seed
h = hashlib.md5()
def add(*arrays):
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
for i in (27, 47, 90, 95, 106):
    t = SupportTask(seed, i, p, "/unused")
    shape, diff = sample_support(item_rng(seed, "mesh_gen/support", t.support_id), t.target_level, p)
    parts = shape.parts(); u = union(parts)
    add(*[q.vertices for q in parts], *[q.faces for q in parts], u.vertices, u.faces)
    h.update(repr(diff).encode())
for k in (2, 3):
    t = ObjectTask(seed, "tool", k, p, "/unused")
    shape = sample_object(item_rng(seed, "mesh_gen/object", t.object_id), "tool", p)
    u = union(list(shape.parts)); add(u.vertices, u.faces, *[q.vertices for q in shape.parts])
print(h.hexdigest())
"""
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _digest(**env) -> str:
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env={**os.environ, **env},
                         capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_procedural_shapes_are_the_same_bytes_under_other_cpu_kernels():
    base = _digest()
    assert _digest(OPENBLAS_CORETYPE="Haswell") == base
    assert _digest(OPENBLAS_CORETYPE="Prescott") == base
    assert _digest(NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR",
                   OPENBLAS_CORETYPE="Haswell") == base
