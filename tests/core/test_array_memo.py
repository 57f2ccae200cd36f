"""`lidarjax._util.ArrayMemo`: host results memoised on the identity of JAX arrays (the scan's
node choice), dropped when an array dies, never for mutable or traced inputs."""

import gc

import jax
import jax.numpy as jnp
import numpy as np

from lidarjax._util import ArrayMemo


def test_memo_by_identity_dropped_with_its_arrays():
    memo = ArrayMemo(size=3)
    calls = []

    def compute(tag):
        calls.append(tag)
        return tag

    a, b = jnp.arange(3.0), jnp.ones(2)
    assert memo((a, b), lambda: compute("ab")) == "ab"
    assert memo((a, b), lambda: compute("again")) == "ab"  # same objects: memoised
    assert memo((jnp.arange(3.0), b), lambda: compute("new a")) == "new a"  # equal values, new object
    assert calls == ["ab", "new a"]
    assert len(memo._entries) == 1  # the temporary array died: its entry went with it
    del a
    gc.collect()
    assert len(memo._entries) == 0
    # at most `size` entries
    keep = [jnp.full(2, float(i)) for i in range(5)]
    for i, x in enumerate(keep):
        memo((x,), lambda i=i: i)
    assert len(memo._entries) == 3
    assert memo((keep[4],), lambda: "recomputed") == 4


def test_mutable_and_traced_inputs_are_not_memoised():
    memo = ArrayMemo()
    n = np.zeros(2)
    assert memo((n,), lambda: 1) == 1
    n[0] = 5.0
    assert memo((n,), lambda: 2) == 2  # numpy: mutable, recomputed
    seen = []
    jax.jit(lambda x: memo((x,), lambda: seen.append(1) or x))(jnp.ones(2))
    assert seen == [1] and not memo._entries
