"""The search both design problems share: a coarse global stage over a box of decision
variables, then a quasi-Newton local stage from the best few candidates, every start at once
(`jax.vmap`), with each step's iterate kept (the path) and every objective evaluation counted.

The decision variables ``x`` (physical units) live in a box ``[lo, hi]``, and `fn(x)` returns
``(value, feasible)``: an infeasible point (in a solid, off the grid, outside a polygon, a
non-finite objective) gets `INFEASIBLE` with a zero gradient, which the backtracking line
search rejects, so every accepted iterate of a feasible start is feasible.

The default local stage (`BoxBFGS`) is a projected quasi-Newton method in the unit box
``u = (x - lo) / (hi - lo)``: an active set of the variables at a bound whose gradient points
out of the box (Bertsekas' projected Newton method, with a BFGS inverse Hessian on the free
variables) and an Armijo search along the projection arc, so that a variable can stop exactly
on its bound and the search converges there. Another optimistix minimiser (``solver=``) works
in unbounded variables ``t`` with ``x = lo + (hi - lo) sigmoid(t)`` (the box is never left, and
never reached: an optimum on a bound then ends at ``max_steps``).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._util import map_in_batches

#: The objective value an infeasible point is given (finite, so that the line search backs off).
INFEASIBLE = 1e30


class BoxBFGS(eqx.Module):
    """The default local stage (module docs): projected BFGS in the unit box of the decision
    variables, with an Armijo search along the projection arc.

    - `rtol`, `atol`: converged when an accepted step moves every unit-box variable by less
      than ``atol + rtol |u|`` and the objective by less than ``atol + rtol |f|`` (as
      optimistix's BFGS), or when no step longer than that lowers the objective (the line
      search has shrunk below it), or when every variable sits on a bound its gradient
      points out of (a corner: the projected step is zero).
    - `slope`, `decrease_factor`: the Armijo condition ``f(u(a)) <= f(u) + slope g.(u(a) -
      u)`` and the backtracking factor (optimistix's `BacktrackingArmijo` defaults).
    - `first_step`: the first step's length (largest component) in the unit box; later
      steps are scaled by the BFGS inverse Hessian (first scaled by ``s.y / y.y``).
    - `active_width`: a variable within this much of a bound (in the unit box; less where the
      projected quasi-Newton step is shorter) whose gradient points out is held on the bound.
    """

    rtol: float = 1e-6
    atol: float = 1e-9
    slope: float = 0.1
    decrease_factor: float = 0.5
    first_step: float = 0.1
    active_width: float = 1e-3


def default_solver(dtype=None) -> BoxBFGS:
    """`BoxBFGS`, tolerances ``rtol = 1e-6``, ``atol = 1e-9`` (on the unit-box variables and
    the objective) in float64, ``1e-4`` and ``1e-6`` in float32 (whose rounding of the
    objective is about 1e-7 relative)."""
    if dtype is not None and jnp.finfo(dtype).bits < 64:
        return BoxBFGS(rtol=1e-4, atol=1e-6)
    return BoxBFGS(rtol=1e-6, atol=1e-9)


def check_counts(fname, **counts):
    """One line naming the first of the search's counts (`n_coarse`, `n_starts`, `max_steps`,
    `batch_size`, ...) that is not a positive integer."""
    for name, val in counts.items():
        if int(val) != val or val < 1:
            raise ValueError(f"{fname}: `{name}` must be a positive integer, got {val!r}.")


def message(converged: bool) -> str:
    """The result's message for a feasible optimum: ``"converged"`` or why not."""
    return "converged" if converged else (
        "the local search stopped at max_steps; the best feasible point found is reported")


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


def to_unit(x, lo, hi):
    """The unit-box coordinates ``(x - lo) / (hi - lo)`` of `x`, clipped to ``[0, 1]``."""
    return jnp.clip((x - lo) / jnp.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)


def from_unit(u, lo, hi):
    """``lo + (hi - lo) u``, exactly `hi` at ``u = 1`` (with the same derivative)."""
    x = lo + (hi - lo) * u
    return x + jax.lax.stop_gradient(jnp.where(u >= 1, hi - x, 0.0))


def _iterate(step, state, x, value, max_steps):
    """Run ``step(state) -> (state, x, value, done)`` (`x`, `value`: the last accepted
    iterate) until done or `max_steps` steps. Returns the final state, the number of steps,
    whether it ended done, the path ``(max_steps + 1, d)`` of accepted iterates from `x`
    (the last repeated after the end) and their values (`value` the start's, NaN if None)."""
    path = jnp.broadcast_to(x, (max_steps + 1,) + x.shape)
    values = jnp.full((max_steps + 1,), jnp.nan if value is None else value, x.dtype)
    idx = jnp.arange(max_steps + 1)

    def cond(carry):
        _, k, done, _, _ = carry
        return (~done) & (k < max_steps)

    def body(carry):
        state, k, _, path, values = carry
        state, x, value, done = step(state)
        path = jnp.where((idx > k)[:, None], x, path)
        values = jnp.where(idx >= k, value, values)
        return state, k + 1, done, path, values

    return jax.lax.while_loop(cond, body, (state, jnp.asarray(0), jnp.asarray(False), path,
                                           values))


def _local(fn, problem, x0, lo, hi, solver, max_steps):
    """An optimistix minimiser from every row of `x0` ``(n, d)`` at once, in the unbounded
    variables ``t`` (module docs). Returns per start the final ``x``, its value, the
    gradient in ``x``, the number of steps (one objective evaluation each), whether it
    terminated, the path ``(max_steps + 1, d)`` of accepted iterates in ``x`` and their
    values."""

    def f(t, args):
        value, ok = masked(*fn(problem, to_box(t, lo, hi))[:2])
        return value, ok

    def one(t_start):
        f_struct, aux_struct = jax.eval_shape(lambda: f(t_start, None))
        state = solver.init(f, t_start, None, {}, f_struct, aux_struct, frozenset())

        def step(carry):
            t, state = carry
            t, state, _ = solver.step(f, t, None, {}, state, frozenset())
            done, _ = solver.terminate(f, t, None, {}, state, frozenset())
            return (t, state), to_box(t, lo, hi), state.f_info.f, done

        (t, state), k, done, path, values = _iterate(step, (t_start, state),
                                                     to_box(t_start, lo, hi), None, max_steps)
        # d x / d t = (hi - lo) sigmoid(t) (1 - sigmoid(t))
        sig = jax.nn.sigmoid(t)
        grad = state.f_info.grad / ((hi - lo) * sig * (1 - sig))
        return to_box(t, lo, hi), state.f_info.f, grad, k, done, path, values

    return jax.vmap(one)(from_box(x0, lo, hi))


def _box_direction(solver: BoxBFGS, u, g, h):
    """Bertsekas' projected quasi-Newton direction at `u` (unit box) from the gradient `g`
    and the inverse Hessian `h`: the variables within the active width of a bound whose
    gradient points out go to that bound, the others take the quasi-Newton step of the free
    block (``-h_FF g_F``)."""
    full = jnp.clip(u - h @ g, 0.0, 1.0) - u
    width = jnp.minimum(solver.active_width, jnp.max(jnp.abs(full)))
    at_lo = (u <= width) & (g > 0)
    at_hi = (u >= 1 - width) & (g < 0)
    free = ~(at_lo | at_hi)
    p = -jnp.where(free[:, None] & free[None, :], h, 0.0) @ g
    return jnp.where(at_lo, -u, jnp.where(at_hi, 1 - u, p))


def _box_step(solver: BoxBFGS, f, lo, hi, carry):
    """One evaluation of `BoxBFGS` (`_local_box`): the trial point's value and gradient;
    accepted (Armijo along the projection arc), the BFGS update and the next direction, or
    rejected, a shorter step."""
    u, fu, g, h, p, alpha, u_eval, first, scaled = carry
    f_e, g_e = jax.value_and_grad(f)(u_eval)
    s = u_eval - u
    predicted = g @ s
    accept = first | ((f_e - fu <= solver.slope * predicted) & (predicted <= 0))
    # the BFGS pair on the variables that moved: one held on its bound (s = 0 there) would
    # otherwise pour its gradient change into the free variables' curvature
    y = jnp.where(s == 0, 0.0, g_e - g)
    sy, yy = s @ y, y @ y
    update = accept & ~first & (sy > jnp.finfo(sy.dtype).eps)
    eye = jnp.eye(u.shape[0], dtype=u.dtype)
    h0 = jnp.where(first, eye * solver.first_step / jnp.maximum(jnp.max(jnp.abs(g_e)),
                                                                jnp.finfo(u.dtype).tiny), h)
    h0 = jnp.where(update & ~scaled, eye * sy / jnp.where(yy > 0, yy, 1.0), h0)
    rho = 1.0 / jnp.where(update, sy, 1.0)
    v = eye - rho * jnp.outer(s, y)
    h = jnp.where(update, v @ h0 @ v.T + rho * jnp.outer(s, s), h0)
    small = jnp.all(jnp.abs(s) < solver.atol + solver.rtol * jnp.abs(u_eval))
    still = jnp.abs(f_e - fu) < solver.atol + solver.rtol * jnp.abs(f_e)
    u, fu, g = (jnp.where(accept, a, b) for a, b in ((u_eval, u), (f_e, fu), (g_e, g)))
    p = jnp.where(accept, _box_direction(solver, u, g, h), p)
    alpha = jnp.where(accept, 1.0, solver.decrease_factor * alpha).astype(u.dtype)
    done = ~first & ((accept & small & still) | (~accept & small)) | (accept & jnp.all(p == 0))
    u_next = jnp.clip(u + alpha * p, 0.0, 1.0)
    carry = (u, fu, g, h, p, alpha, u_next, jnp.asarray(False), scaled | update)
    return carry, from_unit(u, lo, hi), fu, done


def _local_box(fn, problem, x0, lo, hi, solver: BoxBFGS, max_steps):
    """`BoxBFGS` from every row of `x0` ``(n, d)`` at once; returns as `_local`. Each step
    evaluates the objective and its gradient once (the first at the start)."""

    def f(u):
        return masked(*fn(problem, from_unit(u, lo, hi))[:2])[0]

    def one(u0):
        d = u0.shape[0]
        zero = jnp.zeros((), u0.dtype)
        carry = (u0, zero, jnp.zeros_like(u0), jnp.eye(d, dtype=u0.dtype), jnp.zeros_like(u0),
                 jnp.ones((), u0.dtype), u0, jnp.asarray(True), jnp.asarray(False))
        carry, k, done, path, values = _iterate(
            lambda c: _box_step(solver, f, lo, hi, c), carry, from_unit(u0, lo, hi), None,
            max_steps)
        u, fu, g = carry[:3]
        return from_unit(u, lo, hi), fu, g / (hi - lo), k, done, path, values

    return jax.vmap(one)(to_unit(x0, lo, hi))


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
    fn = eqx.filter_jit(fn)  # traced once, then batched and differentiated as a jaxpr
    values, ok = map_in_batches(lambda x: fn(problem, x)[:2], cand, batch_size)
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
    local = _local_box if isinstance(solver, BoxBFGS) else _local
    finals, final, grads, k, done, path, pvals = local(fn, problem, starts, lo, hi, solver,
                                                       max_steps)
    final_ok = start_ok & (final < INFEASIBLE)
    best = jnp.argmin(jnp.where(final_ok, final, jnp.inf))
    x = finals[best]
    grad = grads[best]
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
