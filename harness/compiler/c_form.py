"""The schedule's looped C step for the native backend (the grouped compile).

One loop per group runs the kind's function for each member on its slices of the flat state, parameter
and signal vectors (states, parameters and outputs of a block are contiguous in the model's layouts, so
only inputs are gathered), then RK4 over the whole state vector. The function's SX statements are
written into the loop body (:mod:`cpgsim.harness.compiler.c_kernel`: evenly spaced members are read at
``base + i * stride``, no call, no pointer arrays); a function it cannot write is CasADi's generated C,
called once per member. The first stage computes every signal (the recorded ``y``); the inner stages
only the signal *rows* that derivatives read, directly or through other signals, and of those only the
ones that depend on ``t`` or ``x`` (the rest are fixed for the step once the sampled update has run, and
keep the first stage's values); the pass before the sampled update only the rows the update reads, and a
kind's update is merged into the last of those passes of its kind where the order allows
(:func:`_sampled_pass`). Each pruned or merged pass is its own CasADi function of the kind (same
expressions, so the same numbers), and each kind's functions are generated with common subexpression
elimination (a leg's kinematics appear in several of its blocks and again in its update). Kinds without
inputs compute signals and derivatives in one pass in the first stage. Costly subexpressions that a
later pass of the same members would compute again are carried in a per-member buffer instead
(:mod:`cpgsim.harness.compiler.carry`). When no member reads another's signals and nothing is sampled
(:func:`_member_local`: arrays of CPG networks), blocks of :data:`BLOCK` members run their whole RK4
step in small element-major buffers instead of each stage passing over the whole state vector
(:func:`_c_member_local_step`; same arithmetic per element, same numbers). It defines
``cpgsim_step_impl`` with CasADi's calling convention, so every driver of :mod:`cpgsim.harness.native`
runs it unchanged.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from cpgsim.harness.compiler import c_kernel
from cpgsim.harness.compiler.carry import carry
from cpgsim.harness.compiler.schedule import Group, Schedule, group_rows, signals_depending_on


def _derived(g: Group, outs: list[ca.SX], tag: str) -> ca.Function:
    """A function of ``g``'s kind computing ``outs``, named after ``g``'s function with ``_tag`` appended."""
    return g.kind.function(f"{g.fn.name()[len(g.kind.name) + 1:]}_{tag}", outs)


def _group_outputs(g: Group) -> list[ca.SX]:
    """The expression of every output of ``g`` in its kind's generic symbols."""
    return g.fn.call(g.kind.args)


def _stage_variant(s: Schedule) -> np.ndarray:
    """Pool mask of the signals that can change between the RK4 stages of one step.

    A signal row is variant when its expression depends on ``t`` or ``x``, or reads a variant input
    (for any instance of its group); the rest depend only on parameters, discrete states and external
    inputs, which are fixed for the whole step once the sampled update has run.
    """
    return signals_depending_on(s, lambda t, x, z: (t, x))


def _pruned_group(g: Group, keep: list[np.ndarray], tag: str) -> tuple[Group | None, list[int]]:
    """``g`` computing only the rows ``keep[k]`` (a mask per output) of each output; and the input
    columns those rows read. Kept rows are cut into contiguous runs, one output each."""
    exprs, offs, targets = [], [], []
    for k, (expr, mask) in enumerate(zip(_group_outputs(g), keep, strict=True)):
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            continue
        for run in np.split(idx, np.flatnonzero(np.diff(idx) != 1) + 1):
            a, b = int(run[0]), int(run[-1]) + 1
            exprs.append(expr if (a, b) == (0, expr.numel()) else expr[a:b])
            offs.append(g.out_off[k] + a)
            targets.append(g.out_target[k])
    if not exprs:
        return None, []
    u = g.kind.args[3]
    cols = sorted(set(ca.jacobian_sparsity(ca.vertcat(*exprs), u).get_triplet()[1])) if u.numel() else []
    return Group(g.kind, _derived(g, exprs, tag), g.x_off, g.z_off, g.p_off, g.u_idx, offs, targets), cols


def _pruned_levels(s: Schedule, needed: np.ndarray, present: np.ndarray | None,
                   tag: str) -> tuple[list[Group], np.ndarray]:
    """The signal groups, in evaluation order, cut down to the rows pool mask ``needed`` asks for,
    directly or through the inputs of those rows.

    Rows in pool mask ``present`` are not computed (their values are already in the pool); the second
    result is the mask of those that were needed (they must be valid in the pool the pruned groups use).
    """
    needed = needed.copy()
    reused = np.zeros(s.pool_size, dtype=bool)
    out: list[Group] = []
    for level in reversed(s.signal_levels):
        for g in reversed(level):
            keep = []
            for k in range(len(g.out_off)):
                rows = group_rows(g, k).reshape(g.n, -1)
                want = needed[rows]
                if present is not None:
                    reused[rows[want & present[rows]]] = True
                    want = want & ~present[rows]
                keep.append(want.any(axis=0))
            pruned, cols = _pruned_group(g, keep, tag)
            if pruned is None:
                continue
            needed[g.u_idx[:, cols].ravel()] = True
            out.append(pruned)
    out.reverse()
    return out, reused


def _sampled_pass(pre: list[Group], discrete: list[Group]) -> list[Group]:
    """The groups of the sampled update in call order: the signal groups ``pre`` (pruned to what the update
    reads), then the discrete groups.

    A kind's discrete group is merged into the last of its signal groups in ``pre`` (one function of both,
    with common subexpressions shared: a leg's update recomputes the kinematics its signals hold) when it
    reads no signal written at or after that group; otherwise it runs after all of them.
    """
    seq = list(pre)
    rest: list[Group] = []
    for d in discrete:
        at = [i for i, g in enumerate(seq) if g.kind is d.kind and np.array_equal(g.x_off, d.x_off)
              and all(t == "pool" for t in g.out_target)]
        if not at:
            rest.append(d)
            continue
        i = at[-1]
        later = np.concatenate([group_rows(g, k) for g in seq[i:] for k in range(len(g.out_off))])
        if np.isin(d.u_idx, later).any():
            rest.append(d)
            continue
        g = seq[i]
        fn = _derived(g, _group_outputs(g) + _group_outputs(d), "sampled")
        seq[i] = Group(g.kind, fn, g.x_off, g.z_off, g.p_off, d.u_idx, [*g.out_off, *d.out_off],
                       [*g.out_target, *d.out_target])
    return seq + rest


def c_step_source(s: Schedule, dt: float, substeps: int, carry_costly: bool = True,
                  inline_kernels: bool = True, member_blocks: bool = True) -> str:
    """C source defining ``cpgsim_step_impl`` / ``cpgsim_step_impl_work`` for schedule ``s`` (see module doc).

    ``carry_costly``: costly subexpressions repeated between the sampled update's pass and the first
    stage's signal passes are computed once (:mod:`cpgsim.harness.compiler.carry`). ``inline_kernels``:
    each group's function is written into its loop (:mod:`cpgsim.harness.compiler.c_kernel`) where it
    can be; else every member calls CasADi's generated function (the same numbers, bit for bit).
    ``member_blocks``: when every member's step is its own (:func:`_member_local`), blocks of members run
    their whole RK4 step in L1-sized buffers instead of each stage passing over the whole state vector."""
    fused, inner, reused, sample, first, n_carry = _step_passes(s, carry_costly)
    local = _member_local(s, fused, n_carry) if inline_kernels and member_blocks else None
    groups = list({id(g): g for g in first + s.derivative_groups + inner + sample}.values())
    parts, names = _c_group_parts(s, groups, inline_kernels)
    reused_rows = np.flatnonzero(reused[:s.n_sig])
    if reused_rows.size:
        parts.append(_c_array("cpgsim_reused", reused_rows))
        keep_reused = (f"if (S != Sw) for (i = 0; i < {reused_rows.size}; ++i) "
                       "Sw[cpgsim_reused[i]] = S[cpgsim_reused[i]];")
    else:
        keep_reused = ""
    parts.append(_c_pass_functions(s, names, fused, sample, first, inner)
                 + _c_step_impl(s, dt, substeps, n_carry, bool(local), keep_reused))
    if local:
        parts.insert(-1, _c_local_step_impl(s, local, first, names, dt, substeps))
    return "".join(parts)


def _step_passes(s: Schedule, carry_costly: bool):
    """The groups of each pass of the step: ``(fused, inner, reused, sample, first, n_carry)``.

    ``fused``: first-stage groups doing signals and derivatives in one call (by ``id`` of the signal
    group); ``inner``: the inner RK4 stages' signal groups and ``reused`` the signal rows they keep from
    the first stage; ``sample``: the sampled update's pass; ``first``: the first stage's signal passes;
    ``n_carry``: the carry buffer's size when costly subexpressions are carried between passes."""
    fused = _fused_first_stage(s)
    inner, reused = _pruned_levels(s, s.reads(s.derivative_groups), ~_stage_variant(s), "stage")
    pre = _pruned_levels(s, s.reads(s.discrete_groups), None, "pre")[0] if s.has_discrete else []
    sample = _sampled_pass(pre, s.discrete_groups)
    first = [fused.get(id(g), g) for lv in s.signal_levels for g in lv]
    n_carry = 0
    if carry_costly:
        (sample, first), n_carry = carry(s, [sample, first])
    return fused, inner, reused, sample, first, n_carry


def _c_group_parts(s: Schedule, groups: list[Group], inline_kernels: bool) -> tuple[list[str], dict[int, str]]:
    """The source's opening parts: CasADi's C for the groups not written inline, the kernel prelude, and
    each group's tables and loop (``cg<i>_run``); with each group's C name by ``id``."""
    from cpgsim.harness.native import casadi_c_source

    inlined = {id(g) for g in groups if inline_kernels and c_kernel.inlinable(g.fn)}
    source = casadi_c_source([g.fn for g in groups if id(g) not in inlined], "cpgsim_kinds")
    parts = [source, c_kernel.PRELUDE, "\n/* ---- grouped step (harness/compiler/c_form.py) ---- */\n"]
    names: dict[int, str] = {}
    for gi, g in enumerate(groups):
        names[id(g)] = f"cg{gi}"
        parts.append(_c_tables(f"cg{gi}", g, s.n_sig, s.pool_size, id(g) in inlined))
        loop = _c_inlined_loop if id(g) in inlined else _c_group_loop
        parts.append(loop(f"cg{gi}", g, s.n_sig, s.pool_size))
    return parts, names


def _c_pass_functions(s: Schedule, names: dict[int, str], fused: dict, sample: list[Group],
                      first: list[Group], inner: list[Group]) -> str:
    """The four pass functions calling the groups' loops: the sampled update, the inner stages' signals,
    the derivatives and the first RK4 stage."""
    def calls(gs) -> str:
        return "\n".join(f"  {names[id(g)]}_run(t, x, z, p, S, E, x_out, z_out, C);" for g in gs)

    fused_kinds = {id(g.kind) for g in fused.values()}
    sample_calls = calls(sample)
    first_calls = calls(first)
    first_deriv_calls = calls(g for g in s.derivative_groups if id(g.kind) not in fused_kinds)
    inner_calls = calls(inner)
    deriv_calls = calls(s.derivative_groups)
    return f"""
/* S: the signals (model signal order); E: external inputs, then one zero (see the group tables) */

/* the sampled update: the signals it reads, directly or through other signals (before the update), then
   the resets and updates into x_out, z_out (a kind's update merged into its last signal pass there) */
static void cpgsim_sample(double t, const double *x, const double *z, const double *p, double *S,
                          const double *E, double *x_out, double *z_out, double *C) {{
  (void)t; (void)x; (void)z; (void)p; (void)S; (void)E; (void)x_out; (void)z_out; (void)C;
{sample_calls}
}}

/* inner RK4 stages: only the signal rows that derivatives read, directly or through other signals, and
   of those only the rows that depend on t or x (the others keep the first stage's values) */
static void cpgsim_signals_read(double t, const double *x, const double *z, const double *p, double *S,
                                const double *E, double *C) {{
  double *x_out = 0, *z_out = 0;
  (void)t; (void)x; (void)z; (void)p; (void)S; (void)E; (void)x_out; (void)z_out; (void)C;
{inner_calls}
}}

static void cpgsim_xdot(double t, const double *x, const double *z, const double *p, double *S, const double *E,
                        double *x_out, double *C) {{
  double *z_out = 0;
  (void)z_out; (void)C;
{deriv_calls}
}}

/* first RK4 stage: every signal and the derivatives; kinds without inputs do both in one call */
static void cpgsim_first_stage(double t, const double *x, const double *z, const double *p, double *S,
                               const double *E, double *x_out, double *C) {{
  double *z_out = 0;
  (void)z_out; (void)C;
{first_calls}
{first_deriv_calls}
}}


"""


def _c_step_impl(s: Schedule, dt: float, substeps: int, n_carry: int, local: bool, keep_reused: str) -> str:
    """``cpgsim_step_impl_work`` and ``cpgsim_step_impl``: the sampled update, then ``substeps`` RK4
    substeps over the pass functions (or, with ``local``, a jump to ``cpgsim_step_local``)."""
    h = dt / substeps
    nx, nz, nsig, nu = s.nx, s.nz, s.n_sig, s.n_u
    if s.has_discrete:
        start = (f"for (i = 0; i < {nx}; ++i) xa[i] = x[i];\n  for (i = 0; i < {nz}; ++i) zb[i] = z[i];\n"
                 "  cpgsim_sample(t0, x, z, p, Sw, E, xa, zb, C);\n"
                 "  xp = xa; zp = zb;")
    else:
        start = "xp = x; zp = z;"
    return f"""#define CPGSIM_NX {max(nx, 1)}
#define CPGSIM_NZ {max(nz, 1)}
#define CPGSIM_NSIG {max(nsig, 1)}
#define CPGSIM_NE {nu + 1}
#define CPGSIM_NC {max(n_carry, 1)}

int cpgsim_step_impl_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {{
  *sz_arg = 5; *sz_res = 3; *sz_iw = 0;
  *sz_w = CPGSIM_NSIG + CPGSIM_NE + 7 * CPGSIM_NX + CPGSIM_NZ + CPGSIM_NC;
  return 0;
}}

/* One macro step (Yu/Fukuhara blocks or any other): sampled update, then {substeps} RK4 substep(s);
   y = the signals after the update at t0. Same arithmetic, in the same order, as the flat compile. */
int cpgsim_step_impl(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {{
{"  return cpgsim_step_local(arg, res, w);  /* c_form._member_local */" if local else ""}
  const double t0 = arg[0] ? arg[0][0] : 0.0;
  const double *x = arg[1], *z = arg[2], *u = arg[3], *p = arg[4];
  double *Sw = w, *E = Sw + CPGSIM_NSIG, *xa = E + CPGSIM_NE, *xb = xa + CPGSIM_NX, *k1 = xb + CPGSIM_NX;
  double *k2 = k1 + CPGSIM_NX, *k3 = k2 + CPGSIM_NX, *k4 = k3 + CPGSIM_NX, *xs = k4 + CPGSIM_NX, *zb = xs + CPGSIM_NX;
  double *C = zb + CPGSIM_NZ;  /* the carry buffer (harness/compiler/carry.py) */
  double *S = res[2] ? res[2] : Sw, *xn;
  const double *xp, *zp;
  long i;
  int s;
  (void)iw; (void)mem; (void)xb; (void)zb; (void)C;
  for (i = 0; i < {nu}; ++i) E[i] = u[i];
  E[{nu}] = 0.0;
  {start}
  for (s = 0; s < {substeps}; ++s) {{
    const double ti = t0 + s * {h!r};
    xn = (s == {substeps - 1} && res[0]) ? res[0] : (s % 2 ? xa : xb);
    if (s == 0) {{ cpgsim_first_stage(ti, xp, zp, p, S, E, k1, C); {keep_reused} }}
    else {{ cpgsim_signals_read(ti, xp, zp, p, Sw, E, C); cpgsim_xdot(ti, xp, zp, p, Sw, E, k1, C); }}
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h / 2!r} * k1[i];
    cpgsim_signals_read(ti + {h / 2!r}, xs, zp, p, Sw, E, C);
    cpgsim_xdot(ti + {h / 2!r}, xs, zp, p, Sw, E, k2, C);
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h / 2!r} * k2[i];
    cpgsim_signals_read(ti + {h / 2!r}, xs, zp, p, Sw, E, C);
    cpgsim_xdot(ti + {h / 2!r}, xs, zp, p, Sw, E, k3, C);
    for (i = 0; i < {nx}; ++i) xs[i] = xp[i] + {h!r} * k3[i];
    cpgsim_signals_read(ti + {h!r}, xs, zp, p, Sw, E, C);
    cpgsim_xdot(ti + {h!r}, xs, zp, p, Sw, E, k4, C);
    for (i = 0; i < {nx}; ++i) xn[i] = xp[i] + {h / 6!r} * (((k1[i] + 2. * k2[i]) + 2. * k3[i]) + k4[i]);
    xp = xn;
  }}
  if (res[0] && xp != res[0]) for (i = 0; i < {nx}; ++i) res[0][i] = xp[i];
  if (res[1]) for (i = 0; i < {nz}; ++i) res[1][i] = zp[i];
  return 0;
}}
"""


def _c_local_step_impl(s: Schedule, pairs: list[tuple[Group, Group]], first: list[Group], names: dict[int, str],
                       dt: float, substeps: int) -> str:
    """``cpgsim_step_impl`` when every member's step is its own (:func:`_member_local`): the stateless
    signal groups, then one loop per derivative group running each member's whole RK4 step."""
    local_first = {id(f) for f, _ in pairs}
    loops, calls = [], []
    for f, d in pairs:
        tag = f"{names[id(f)]}_{names[id(d)]}"
        loops.append(_c_member_local_step(tag, names[id(f)], names[id(d)], f, d, dt, substeps))
        calls.append(f"  {tag}_local(t0, x, z, p, S, xn);")
    stateless = "\n".join(f"  {names[id(g)]}_run(t0, x, z, p, S, E, 0, 0, 0);" for g in first
                          if id(g) not in local_first)
    nl = "\n"
    return "".join(loops) + f"""
/* Every member's step depends on that member alone (no inputs, nothing sampled): each derivative
   group's members run their whole RK4 step in blocks of L1-sized buffers (c_form._member_local). */
static int cpgsim_step_local(const casadi_real **arg, casadi_real **res, casadi_real *w) {{
  const double t0 = arg[0] ? arg[0][0] : 0.0;
  const double *x = arg[1], *z = arg[2], *u = arg[3], *p = arg[4];
  double *Sw = w, *E = Sw + {max(s.n_sig, 1)}, *xa = E + {s.n_u + 1};  /* the work layout of cpgsim_step_impl */
  double *S = res[2] ? res[2] : Sw, *xn = res[0] ? res[0] : xa;
  long i;
  (void)u;
  for (i = 0; i < {s.n_u}; ++i) E[i] = u[i];
  E[{s.n_u}] = 0.0;
{stateless}
{nl.join(calls)}
  if (res[1]) for (i = 0; i < {s.nz}; ++i) res[1][i] = z[i];
  return 0;
}}
"""


def _fused_first_stage(s: Schedule) -> dict[int, Group]:
    """Signal group id -> one group computing the kind's signals and derivatives together.

    For kinds without inputs whose signals are one group over all instances (an autonomous CPG
    network): its derivatives need nothing from other kinds, so the first RK4 stage computes both in
    one pass over the instances (one read of their states and parameters, shared subexpressions).
    """
    deriv = {id(g.kind): g for g in s.derivative_groups}
    out: dict[int, Group] = {}
    for level in s.signal_levels:
        for g in level:
            kind = g.kind
            if kind.sizes[2] or id(kind) not in deriv or g.n != len(kind.members):
                continue
            if sum(int(g.fn.size1_out(k)) for k in range(g.fn.n_out())) != sum(
                    int(e.numel()) for e in kind.outputs.values()):
                continue  # the kind's signals are split over levels: not one group
            outs = [g.fn.call(kind.args)[k] for k in range(g.fn.n_out())] + [kind.xdot]
            fn = kind.function("first_stage", outs)
            out[id(g)] = Group(kind, fn, g.x_off, g.z_off, g.p_off, g.u_idx, [*g.out_off, g.x_off],
                               [*g.out_target, "x"])
    return out


def _c_array(name: str, values: np.ndarray) -> str:
    vals = ",".join(str(int(v)) for v in np.asarray(values).ravel()) or "0"
    return f"static const long long {name}[] = {{{vals}}};\n"


def _input_columns(g: Group, n_sig: int, pool_size: int) -> tuple[np.ndarray, list[str]]:
    """Per input column: where it reads ("S" signals, "E" external, "SE" mixed, "C" the carry buffer) and
    the table to read it with."""
    ui = g.u_idx.copy()
    modes = []
    for j in range(ui.shape[1]):
        col = g.u_idx[:, j]
        if np.all(col >= pool_size):
            modes.append("C")
            ui[:, j] = col - pool_size
        elif np.all(col < n_sig):
            modes.append("S")
        elif np.all(col >= n_sig):
            modes.append("E")
            ui[:, j] = col - n_sig
        else:
            modes.append("SE")
    return ui, modes


def _input_element(tag: str, modes: list[str], j: int, nu: int, n_sig: int) -> str:
    """C reading input element ``j`` of member ``i`` from where :func:`_input_columns` says it lives."""
    ref = f"{tag}_ui[i * {nu} + {j}]"
    if modes[j] in ("S", "E", "C"):  # the signal pool, the external inputs, the carry buffer
        return f"{modes[j]}[{ref}]"
    return f"({ref} < {n_sig} ? S[{ref}] : E[{ref} - {n_sig}])"


def _c_tables(tag: str, g: Group, n_sig: int, pool_size: int, inlined: bool = False) -> str:
    """The group's offset tables; an inlined loop (:mod:`.c_kernel`) needs only the unevenly spaced ones."""
    ui, _ = _input_columns(g, n_sig, pool_size)
    tables = {"xo": g.x_off, "zo": g.z_off, "po": g.p_off}
    tables.update({f"o{k}": off for k, off in enumerate(g.out_off) if g.out_target[k] in ("pool", "carry")})
    out = [_c_array(f"{tag}_ui", ui)] if ui.size or not inlined else []
    for name, values in tables.items():
        if not inlined or c_kernel.offset(tag, name, values).startswith(f"{tag}_"):
            out.append(_c_array(f"{tag}_{name}", values))
    return "".join(out)


def _c_group_loop(tag: str, g: Group, n_sig: int, pool_size: int) -> str:
    nu = g.u_idx.shape[1]
    _, modes = _input_columns(g, n_sig, pool_size)
    fname = g.fn.name()
    where = {"pool": ("S", "o{k}"), "carry": ("C", "o{k}"), "x": ("x_out", "xo"), "z": ("z_out", "zo")}
    res_lines = []
    for k, what in enumerate(g.out_target):
        base, table = where[what]
        res_lines.append(f"    res[{k}] = {base} + {tag}_{table.format(k=k)}[i];")
    gathers = [f"    ub[{j}] = {_input_element(tag, modes, j, nu, n_sig)};" for j in range(nu)]
    n_res = max(1, len(g.out_target))
    nl = "\n"
    return f"""
static void {tag}_run(double t, const double *x, const double *z, const double *p, double *S, const double *E,
                     double *x_out, double *z_out, double *C) {{
  long i;
  double ub[{max(nu, 1)}];
  const double *arg[5];
  double *res[{n_res}];
  double w[{max(1, g.fn.sz_w())}];
  long long iw[{max(1, g.fn.sz_iw())}];
  (void)x_out; (void)z_out; (void)S; (void)E; (void)C;
  arg[0] = &t; arg[3] = ub;
  for (i = 0; i < {g.n}; ++i) {{
{nl.join(gathers)}
    arg[1] = x + {tag}_xo[i]; arg[2] = z + {tag}_zo[i]; arg[4] = p + {tag}_po[i];
{nl.join(res_lines)}
    {fname}(arg, res, iw, w, 0);
  }}
}}
"""


def _c_inlined_loop(tag: str, g: Group, n_sig: int, pool_size: int) -> str:
    """``g``'s loop with its function's statements written into the body (:mod:`.c_kernel`)."""
    nu = g.u_idx.shape[1]
    _, modes = _input_columns(g, n_sig, pool_size)

    def u_element(j: int) -> str:
        return _input_element(tag, modes, j, nu, n_sig)

    xo = c_kernel.offset(tag, "xo", g.x_off)
    read = {0: lambda j: "t", 1: f"(x + {xo})", 2: f"(z + {c_kernel.offset(tag, 'zo', g.z_off)})",
            3: u_element, 4: f"(p + {c_kernel.offset(tag, 'po', g.p_off)})"}
    where = {"pool": "S", "carry": "C", "x": "x_out", "z": "z_out"}
    write = {}
    for k, what in enumerate(g.out_target):
        if what == "x":
            off = xo
        elif what == "z":
            off = c_kernel.offset(tag, "zo", g.z_off)
        else:
            off = c_kernel.offset(tag, f"o{k}", g.out_off[k])
        write[k] = f"({where[what]} + {off})"
    nl = "\n"
    return f"""
static void {tag}_run(double t, const double *x, const double *z, const double *p, double *S, const double *E,
                     double *x_out, double *z_out, double *C) {{
  long i;
  (void)t; (void)x; (void)z; (void)p; (void)x_out; (void)z_out; (void)S; (void)E; (void)C;
  for (i = 0; i < {g.n}; ++i) {{
{nl.join(c_kernel.body(g.fn, read, write))}
  }}
}}
"""


BLOCK = 4
"""Members per block of the member-local RK4 loop (4: 14.0 ns per neuron-step at 18,000 neurons, 8: 15.0,
2: 16.8, 16: 14.4; 2026-12-03, SSE2 doubles)."""


def _member_local(s: Schedule, fused: dict[int, Group], n_carry: int) -> list[tuple[Group, Group]] | None:
    """The (first-stage, derivative) group pairs when every member's RK4 step depends on that member alone:
    no group reads an input (no member sees another's signals), nothing is sampled or carried, every
    derivative group's first stage is one fused group written into its loop (:func:`_fused_first_stage`),
    and the derivative groups' members hold every state once. Else None."""
    groups = [g for lv in s.signal_levels for g in lv] + list(s.derivative_groups)
    if s.has_discrete or n_carry or any(g.u_idx.shape[1] for g in groups) or not s.derivative_groups:
        return None
    first_of = {id(g.kind): g for g in fused.values()}
    pairs, covered = [], np.zeros(s.nx, dtype=int)
    for d in s.derivative_groups:
        f = first_of.get(id(d.kind))
        if f is None or not (c_kernel.inlinable(f.fn) and c_kernel.inlinable(d.fn)):
            return None
        if not np.array_equal(f.x_off, d.x_off):
            return None
        nx_k = d.kind.sizes[0]
        for off in d.x_off:
            covered[off:off + nx_k] += 1
        pairs.append((f, d))
    return pairs if np.all(covered == 1) else None


def _c_member_local_step(tag: str, f_tag: str, d_tag: str, f: Group, d: Group, dt: float, substeps: int,
                         block: int = BLOCK) -> str:
    """One loop over ``d``'s members running their whole RK4 step ``block`` members at a time.

    The block's states, stages and parameters sit in small buffers laid out element-major
    (``xs[j][b]``: element ``j`` of the block's member ``b``), so each stage is one loop over the block
    with unit-stride reads that the compiler turns into SIMD; the buffers stay in the L1 cache, so the
    whole-vector passes of the RK4 sums over memory are gone. The last block is padded with the last
    member (computed again, its same values written again). The same arithmetic per element, in the same
    order, as the whole-vector step, so the same numbers bit for bit."""
    nx_k, np_k = d.kind.sizes[0], d.kind.sizes[3]
    h = dt / substeps

    def member(table: str, offsets, group_tag: str = d_tag) -> str:
        return c_kernel.offset(group_tag, table, offsets, index="m")

    signal_writes = {k: f"(S + {member(f'o{k}', f.out_off[k], f_tag)})"
                     for k, what in enumerate(f.out_target) if what == "pool"}
    last = len(f.out_target) - 1
    assert f.out_target[last] == "x"

    def stage(fn: ca.Function, time: str, x_from: str, k_into: str, signals: bool) -> str:
        write = dict(signal_writes) if signals else {}
        write[last if signals else 0] = lambda j, k=k_into: f"{k}[{j}][b]"
        read = {0: lambda j: time, 1: lambda j, x=x_from: f"{x}[{j}][b]", 2: f"(z + {member('zo', d.z_off)})",
                4: lambda j: f"pb[{j}][b]"}
        lines = "\n".join("    " + line for line in c_kernel.body(fn, read, write, lazy=False))  # SIMD blocks
        return f"    for (b = 0; b < {block}; ++b) {{\n      const long m = mb[b];\n      (void)m;\n{lines}\n    }}"

    def axpy(out: str, c: float, k: str) -> str:
        return (f"    for (j = 0; j < {nx_k}; ++j) for (b = 0; b < {block}; ++b) "
                f"{out}[j][b] = xp[j][b] + {c!r} * {k}[j][b];")

    nl = "\n"
    per_substep = []
    for sub in range(substeps):
        ti = f"(t0 + {sub} * {h!r})"
        first = (stage(f.fn, ti, "xp", "k1", True) if sub == 0 else stage(d.fn, ti, "xp", "k1", False))
        per_substep.append(nl.join([
            first,
            axpy("xs", h / 2, "k1"), stage(d.fn, f"({ti} + {h / 2!r})", "xs", "k2", False),
            axpy("xs", h / 2, "k2"), stage(d.fn, f"({ti} + {h / 2!r})", "xs", "k3", False),
            axpy("xs", h, "k3"), stage(d.fn, f"({ti} + {h!r})", "xs", "k4", False),
            f"    for (j = 0; j < {nx_k}; ++j) for (b = 0; b < {block}; ++b)\n"
            f"      xp[j][b] = xp[j][b] + {h / 6!r} * (((k1[j][b] + 2. * k2[j][b]) + 2. * k3[j][b]) + k4[j][b]);",
        ]))
    x_at, p_at = member("xo", d.x_off), member("po", d.p_off)
    buffers = ", ".join(f"{name}[{nx_k}][{block}]" for name in ("xp", "xs", "k1", "k2", "k3", "k4"))
    return f"""
static void {tag}_local(double t0, const double *x, const double *z, const double *p, double *S, double *x_out) {{
  long i, b, m, mb[{block}];
  int j;
  double {buffers}, pb[{max(np_k, 1)}][{block}];
  (void)z; (void)p; (void)S; (void)pb; (void)m;
  for (i = 0; i < {d.n}; i += {block}) {{
    for (b = 0; b < {block}; ++b) mb[b] = i + b < {d.n} ? i + b : {d.n - 1};
    for (b = 0; b < {block}; ++b) {{
      m = mb[b];
      for (j = 0; j < {nx_k}; ++j) xp[j][b] = x[{x_at} + j];
      for (j = 0; j < {np_k}; ++j) pb[j][b] = p[{p_at} + j];
    }}
{nl.join(per_substep)}
    for (b = 0; b < {block}; ++b) {{ m = mb[b]; for (j = 0; j < {nx_k}; ++j) x_out[{x_at} + j] = xp[j][b]; }}
  }}
}}
"""
