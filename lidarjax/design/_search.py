"""The search both design problems share: a coarse global stage over a box of decision
variables, then a quasi-Newton local stage (optimistix) from the best few candidates, every
start at once (`jax.vmap`), with each step's iterate kept (the path) and every objective
evaluation counted.

The decision variables ``x`` (physical units) live in a box ``[lo, hi]``; the local stage
works in unbounded variables ``t`` with ``x = lo + (hi - lo) sigmoid(t)`` (so the box is never
left), and `fn(x)` returns ``(value, feasible)``: an infeasible point (in a solid, off the
grid, outside a polygon, a non-finite objective) gets `INFEASIBLE` with a zero gradient, which
the backtracking line search of the quasi-Newton solver rejects, so every accepted iterate of
a feasible start is feasible.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

#: The objective value an infeasible point is given (finite, so that the line search backs off).
INFEASIBLE = 1e30


def default_solver(dtype=None) -> optx.AbstractMinimiser:
    """BFGS with a backtracking Armijo line search, tolerances ``rtol = 1e-6``, ``atol = 1e-9``
    (on the unbounded variables and the objective) in float64, ``1e-4`` and ``1e-6`` in float32
    (whose rounding of the objective is about 1e-7 relative)."""
    if dtype is not None and jnp.finfo(dtype).bits < 64:
        return optx.BFGS(rtol=1e-4, atol=1e-6)
    return optx.BFGS(rtol=1e-6, atol=1e-9)


def unit_grid(n_dims: int, n_candidates: int) -> np.ndarray:
    """``(m, n_dims)`` points of a regular grid in the open unit cube (cell centres),
    ``k = max(2, round(n_candidates ** (1 / n_dims)))`` per axis, ``m = k ** n_dims``."""
    k = max(2, int(round(float(n_candidates) ** (1.0 / n_dims))))
    axes = [(np.arange(k) + 0.5) / k] * n_dims
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=-1)


def to_box(t, lo, hi):
    return lo + (hi - lo) * jax.nn.sigmoid(t)


def from_box(x, lo, hi):
    u = jnp.clip((x - lo) / jnp.where(hi > lo, hi - lo, 1.0), 1e-6, 1 - 1e-6)
    return jnp.log(u) - jnp.log1p(-u)


def masked(value, feasible):
    """`value` where `feasible` (and finite), else `INFEASIBLE` with a zero gradient."""
    ok = feasible & jnp.isfinite(value)
    return jnp.where(ok, value, jnp.asarray(INFEASIBLE, value.dtype)), ok


def _local(fn, problem, t0, lo, hi, solver, max_steps):
    """Quasi-Newton from every row of `t0` ``(n, d)`` at once. Returns per start the final
    ``t``, its value and feasibility, the number of steps (one objective evaluation each),
    whether it terminated, the path ``(max_steps + 1, d)`` of accepted iterates in ``x``
    (the last repeated after the end) and their values."""

    def f(t, args):
        value, ok = masked(*fn(problem, to_box(t, lo, hi))[:2])
        return value, ok

    def one(t_start):
        f_struct, aux_struct = jax.eval_shape(lambda: f(t_start, None))
        state = solver.init(f, t_start, None, {}, f_struct, aux_struct, frozenset())
        x0 = to_box(t_start, lo, hi)
        path = jnp.broadcast_to(x0, (max_steps + 1,) + x0.shape)
        values = jnp.full((max_steps + 1,), jnp.nan, f_struct.dtype)
        idx = jnp.arange(max_steps + 1)

        def cond(carry):
            _, _, k, done, _, _ = carry
            return (~done) & (k < max_steps)

        def body(carry):
            t, state, k, _, path, values = carry
            t, state, _ = solver.step(f, t, None, {}, state, frozenset())
            done, _ = solver.terminate(f, t, None, {}, state, frozenset())
            path = jnp.where((idx > k)[:, None], to_box(t, lo, hi), path)
            values = jnp.where(idx >= k, state.f_info.f, values)
            return t, state, k + 1, done, path, values

        t, state, k, done, path, values = jax.lax.while_loop(
            cond, body, (t_start, state, jnp.asarray(0), jnp.asarray(False), path, values))
        return t, state.f_info.f, state.f_info.grad, k, done, path, values

    return jax.vmap(one)(t0)


#: XLA options for the search's one program on a CPU when `fast_compile` is asked for: LLVM at
#: -O0 without the fusion emitters compiles it about 3x faster (2.4 s against 6.9 s for the
#: gradient of 12 directions, measured) and runs it about 3x slower, which the search's
#: runtime (a fraction of a second against tens of seconds of compilation) can afford. The
#: options apply to this program only; JAX's configuration is not changed.
FAST_CPU_OPTIONS = ({"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False},
                    {"xla_backend_optimization_level": 0})
#: Executables of the search kept for reuse in this process (the least recently used
#: dropped beyond this): a design run compiles one or two structures; each entry holds its
#: objective and static configuration alive, so the cache stays small. Across processes
#: JAX's persistent compilation cache, where enabled, serves the compilation itself.
COMPILED_CACHE_SIZE = 8


def _compiled_run(fn, args, statics, fast):
    """`_run` compiled once per structure (shapes, dtypes, static configuration); with `fast`
    on a CPU, with `FAST_CPU_OPTIONS` (the first set this jaxlib accepts)."""
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    avals = tuple((x.shape, x.dtype, bool(getattr(x, "weak_type", False))) for x in leaves)
    key = (fn, static, treedef, avals, statics, bool(fast), jax.default_backend())
    try:
        hash(key)
    except TypeError:  # an unhashable static part: compile without caching
        return _executable.__wrapped__(*key)(dyn)
    return _executable(*key)(dyn)


@functools.lru_cache(maxsize=COMPILED_CACHE_SIZE)
def _executable(fn, static, treedef, avals, statics, fast, backend):
    """The compiled `_run` for inputs of this structure (`_compiled_run`), lowered from
    their shapes alone."""
    del backend  # part of the cache key only

    def run(dyn):
        return _run(fn, *eqx.combine(dyn, static), *statics)

    shapes = jax.tree_util.tree_unflatten(
        treedef, [jax.ShapeDtypeStruct(s, d, weak_type=w) for s, d, w in avals])
    lowered = jax.jit(run).lower(shapes)
    if fast and jax.default_backend() == "cpu":
        for options in FAST_CPU_OPTIONS:
            try:
                return lowered.compile(compiler_options=options)
            except Exception:  # noqa: BLE001 - an option this jaxlib does not know
                continue
    return lowered.compile()


def _run(fn, problem, cand, lo, hi, solver, max_steps, n_starts, batch_size, grid_shape=None):
    """The whole search as one compiled program (module docs)."""
    values, ok = jax.lax.map(lambda x: fn(problem, x)[:2], cand, batch_size=batch_size)
    ok = ok & jnp.isfinite(values)
    score = jnp.where(ok, values, jnp.inf)
    if grid_shape is not None:  # local minima of the coarse grid first: one start per basin
        n_extra = cand.shape[0] - int(np.prod(grid_shape))
        v = score[n_extra:].reshape(grid_shape)
        is_min = jnp.isfinite(v)
        for axis in range(v.ndim):
            for shift in (1, -1):
                nb = jnp.roll(v, shift, axis=axis)
                edge = jnp.arange(v.shape[axis]) == (0 if shift == 1 else v.shape[axis] - 1)
                edge = edge.reshape([-1 if a == axis else 1 for a in range(v.ndim)])
                is_min &= jnp.where(edge, True, v <= nb)
        rank = jnp.where(is_min.ravel(), 0.0, 1.0)
        rank = jnp.concatenate([jnp.zeros(n_extra), rank])
        order = jnp.lexsort((score, rank))[:n_starts]
    else:
        order = jnp.argsort(score)[:n_starts]
    starts = cand[order]
    start_ok = ok[order]
    t, final, grad_t, k, done, path, pvals = _local(fn, problem, from_box(starts, lo, hi), lo,
                                                    hi, solver, max_steps)
    finals = to_box(t, lo, hi)
    final_ok = start_ok & (final < INFEASIBLE)
    best = jnp.argmin(jnp.where(final_ok, final, jnp.inf))
    x = finals[best]
    # the gradient at the last accepted iterate, from the solver (d f / d t), in x by the
    # chain rule: dx/dt = (hi - lo) sigmoid(t) (1 - sigmoid(t))
    sig = jax.nn.sigmoid(t[best])
    grad = grad_t[best] / ((hi - lo) * sig * (1 - sig))
    # value and auxiliary output at the optimum and at its start: one forward program
    value, feasible, aux = jax.lax.map(lambda y: fn(problem, y), jnp.stack([x, starts[best]]))
    aux_start = jax.tree_util.tree_map(lambda a: a[1], aux)
    aux = jax.tree_util.tree_map(lambda a: a[0], aux)
    value, feasible = value[0], feasible[0]
    return dict(values=values, ok=ok, order=order, starts=starts, start_ok=start_ok,
                finals=finals, final=final, final_ok=final_ok, steps=k, done=done, paths=path,
                path_values=pvals, best=best, x=x, value=value, feasible=feasible, grad=grad,
                aux=aux, aux_start=aux_start)


def search(fn, problem, lo, hi, *, x_init=None, n_coarse: int, n_starts: int, solver,
           max_steps: int, batch_size: int = 64, fast_compile: bool = True):
    """Coarse grid, then the local stage from `n_starts` feasible candidates (the coarse
    grid's local minima first, best first, so that the starts lie in different basins; then
    the best of the others), then
    the value, gradient and auxiliary output at the best point and at its start: one
    compiled program. `fn(problem, x)` returns ``(value, feasible, aux)``.

    `x_init` (optional ``(d,)``) is added to the candidates. Returns a dict of host arrays:
    ``x`` (best), ``value``, ``gradient``, ``aux``, ``aux_start``, ``feasible`` (some
    candidate was), ``converged``, ``start``, ``start_value``, ``path`` ``(k, d)`` and
    ``path_values`` of the winning start, ``n_evaluations`` (every objective evaluation the
    program ran: coarse candidates, local steps, the final point's value and gradient and the
    start's rose), ``coarse`` ``(m, d)`` and ``coarse_values`` (NaN where infeasible)."""
    lo_h, hi_h = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    d = lo_h.size
    cand = lo_h + (hi_h - lo_h) * unit_grid(d, n_coarse)
    if x_init is not None:
        cand = np.concatenate([np.asarray(x_init, np.float64)[None], cand])
    m = cand.shape[0]
    n = int(min(n_starts, m))
    k = max(2, int(round(float(n_coarse) ** (1.0 / d))))
    r = _compiled_run(fn, (problem, jnp.asarray(cand, lo.dtype), lo, hi, solver),
                      (int(max_steps), n, int(min(batch_size, m)), (k,) * d), fast_compile)
    r = jax.tree_util.tree_map(np.asarray, r)
    ok = r["ok"]
    b = int(r["best"])
    steps = r["steps"]
    out = {"coarse": cand, "coarse_values": np.where(ok, r["values"], np.nan),
           "n_coarse": m, "n_feasible": int(ok.sum()),
           "n_evaluations": m + int(steps.sum()) + 2}
    kmax = int(steps[b]) + 1
    path, pvals = r["paths"][b, :kmax], r["path_values"][b, :kmax]
    keep = np.concatenate([[True], np.any(np.diff(path, axis=0) != 0, axis=1)])
    feasible = bool(ok.any()) and bool(r["final_ok"][b]) and bool(r["feasible"])
    out.update(x=r["x"], value=float(r["value"]), gradient=r["grad"], aux=r["aux"],
               aux_start=r["aux_start"], feasible=feasible,
               converged=feasible and bool(r["done"][b]), start=r["starts"][b],
               start_value=float(r["values"][r["order"][b]]), path=path[keep],
               path_values=pvals[keep], finals=r["finals"], final_values=r["final"],
               steps=steps)
    return out
