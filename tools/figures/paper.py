#!/usr/bin/python3
"""Figures of pedalwave_paper, from the data it writes into OUT/data/: each NAME.json says which
figure it is ("kind"), its numbers, and the trace CSVs beside it (t, COM, head and tail tips, the
head joint's SEA torque and η, and the body points x_k, z_k when sampled). The PNGs go to OUT.

  flat_com        COM x of the two flat runs                          -> flat_com.png
  friction_torque head-joint SEA torque and its negative peaks (Fig. 7) -> friction_torque.png
  stair           one k_c over the box: shapes and a film strip       -> stair_shapes_<tag>.png,
                                                                         stair_film_<tag>.png
  stair_progress  head height, COM and tail x, η over time per k_c    -> stair_progress.png
  sweep_speed     average speed against k_c (Fig. 9), from sweep.csv  -> sweep_speed.png
  sensitivity_K   speeds against the SEA stiffness K                  -> sensitivity_K.png

    /usr/bin/python3 tools/figures/paper.py paper_out flat_com stair_kc10.1
"""
import os

import pwfig
from pwfig import fmt, np, plt


def cms(v):
    return "—" if v is None else f"{v * 100:.{3 if abs(v) < 0.01 else 2}f} cm/s"


def secs(t):
    return "never" if t is None else f"{t:.1f} s"


def flat_com(out, data, spec):
    fig, ax = plt.subplots(figsize=(10, 5))
    for run in spec["runs"]:
        tr = pwfig.read_csv(os.path.join(data, run["csv"]), required=("t", "com_x"))
        ax.plot(tr["t"], 100 * tr["com_x"], label=run["label"])
    ax.axvline(spec["avg_from"], color="#777", ls="--", lw=1.2, label="t₀ (the average starts)")
    ax.margins(x=0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("COM x [cm]")
    ax.set_title(f"Flat ground: whole-robot COM x (average speed from t = {fmt(spec['avg_from'])} s)")
    ax.legend(loc="upper left")
    pwfig.save(fig, os.path.join(out, "flat_com.png"))


def friction_torque(out, data, spec):
    tr = pwfig.read_csv(os.path.join(data, spec["trace"]), required=("t", "tau_head", "head_x", "com_x", "tail_x"))
    fig, (ax, bx) = pwfig.stacked("Friction change: SEA torque of the head joint (joint N−1), the paper's Fig. 7",
                                  tr["t"], 2, panel_height=2.8, width=11)
    ax.plot(tr["t"], tr["tau_head"], lw=1.1, color=pwfig.CYCLE[0], label="head joint")
    for key, mean, color, marker, what in (("peaks_before", spec.get("mean_before"), pwfig.CYCLE[1], "o", "before"),
                                           ("peaks_after", spec.get("mean_after"), pwfig.CYCLE[2], "s", "after")):
        pk = spec[key]
        extra = f" ({spec['change_label']})" if what == "after" else ""
        ax.plot(pk["t"], pk["tau"], marker, color=color, ms=6, ls="",
                label=f"peaks {what}: mean {fmt(mean)} N·m{extra}")
        if mean is not None:
            ax.axhline(-mean, color=color, ls=":", lw=1.2)
    t_cross = spec.get("t_cross")
    if t_cross is not None:
        for a in (ax, bx):
            a.axvline(t_cross, color=pwfig.RED, lw=1.2, label=f"head tip at x = {fmt(spec['cross_x'])} m" if a is ax else None)
    ax.set_ylabel("τ_s = K(β − α) [N·m]")
    for name, label in (("head_x", "head tip"), ("com_x", "COM"), ("tail_x", "tail tip")):
        bx.plot(tr["t"], tr[name], label=label)
    bx.axhline(spec["cross_x"], color="#777", ls="--", lw=1.2, label="μ changes")
    bx.set_ylabel("x [m]")
    pwfig.finish_stacked(fig, [ax, bx], os.path.join(out, "friction_torque.png"))


def stair(out, data, spec):
    body = pwfig.Body(os.path.join(data, spec["trace"]))
    tag, k_c, t_hi, every = spec["tag"], spec["k_c"], spec["t_hi"], spec["every"]
    scene = spec["scene"]
    pwfig.snake_shapes(os.path.join(out, f"stair_shapes_{tag}.png"),
                       f"Stair, k_c = {fmt(k_c)}: body every {fmt(every, 2)} s, t = 0 … {fmt(t_hi)} s "
                       f"(head tip ●); head on top {secs(spec.get('t_head_on_top'))}, body past "
                       f"{secs(spec.get('t_body_past'))}", body, body.every(every, t_hi), scene)
    film = body.at_times(t_hi * np.arange(12) / 11)
    pwfig.body_film(os.path.join(out, f"stair_film_{tag}.png"), f"Stair, k_c = {fmt(k_c)}: snapshots (head tip ●)",
                    body, film, scene)


def stair_progress(out, data, spec):
    cases = [(c["k_c"], pwfig.read_csv(os.path.join(data, c["trace"]),
                                       required=("t", "head_z", "com_x", "tail_x", "eta_head"))) for c in spec["cases"]]
    t = cases[0][1]["t"] if cases else np.array([])
    fig, (a, b, c) = pwfig.stacked("Stair: progress over time", t, 3, panel_height=2.3, width=11)
    a.axhline(100 * spec["top"], color="#777", ls="--", lw=1.2, label="box top")
    b.axhline(100 * spec["x_near"], color="#777", ls="--", lw=1.2, label="near edge")
    b.axhline(100 * spec["x_far"], color="#777", ls=":", lw=1.2, label="far edge")
    for i, (k_c, tr) in enumerate(cases):
        color, lab = pwfig.CYCLE[i % len(pwfig.CYCLE)], f"k_c = {fmt(k_c)}"
        a.plot(tr["t"], 100 * tr["head_z"], color=color, lw=1.2, label=lab)
        b.plot(tr["t"], 100 * tr["com_x"], color=color, label=lab + " COM")
        b.plot(tr["t"], 100 * tr["tail_x"], color=color, ls="--", label=lab + " tail tip")
        c.plot(tr["t"], tr["eta_head"], color=color, lw=1.2, label=lab)
    a.set_ylabel("head tip z [cm]")
    b.set_ylabel("x [cm]")
    c.set_ylabel("η of head joint [rad]")
    pwfig.finish_stacked(fig, [a, b, c], os.path.join(out, "stair_progress.png"))


def sweep_speed(out, data, spec):
    sw = pwfig.read_csv(os.path.join(data, spec["csv"]), required=("k_c", "speed_m_s", "t_body_past_s"))
    k, v = sw["k_c"], 100 * sw["speed_m_s"]
    fig, ax = plt.subplots(figsize=(10, 5.5))
    ax.plot(k, v, marker="o", ms=3.5, label="ours")
    past = np.isfinite(sw["t_body_past_s"])
    if past.any():
        ax.plot(k[past], v[past], "o", ms=8, mfc="none", mec=pwfig.CYCLE[2], mew=1.5, label="whole body past the box")
    best = spec.get("best")
    if best:
        ax.plot([best["k_c"]], [100 * best["speed"]], "D", color=pwfig.RED, ms=10,
                label=f"best k_c = {fmt(best['k_c'])} ({best['gain_label']})")
    if spec.get("v0") is not None:
        ax.axhline(100 * spec["v0"], color="#777", ls="--", lw=1.2, label="k_c = 0")
    ax.axvline(spec["paper_best_k_c"], color="#777", ls=":", lw=1.2, label=f"paper's best {fmt(spec['paper_best_k_c'])}")
    ax.set_xlabel("k_c")
    ax.set_ylabel("average speed [cm/s]")
    ax.set_title(f"Average forward speed over the stair against k_c ({fmt(spec['duration'])} s each; the paper's Fig. 9)")
    ax.legend(loc="best")
    pwfig.save(fig, os.path.join(out, "sweep_speed.png"))


def sensitivity_K(out, data, spec):
    fig, ax = plt.subplots(figsize=(10, 5.5))
    for key, label, marker in (("flat_high", "flat μ = 0.82", "o"), ("flat_low", "flat μ = 0.40", "s"),
                               ("stair_0", "stair k_c = 0", "^"), ("stair_kc", f"stair k_c = {fmt(spec['k_c'])}", "D")):
        ax.plot(spec["K"], [np.nan if y is None else y for y in spec[key]], marker=marker, label=label)
    ax.axhline(spec["paper_flat_sim"], color="#777", ls="--", lw=1.2, label="paper's simulation, flat μ = 0.82")
    ax.set_xscale("log")
    pwfig.plain_log_ticks(ax.xaxis)
    ax.set_xlabel("K [N·m/rad]")
    ax.set_ylabel("average speed [cm/s]")
    ax.set_title(f"Speed against the SEA stiffness K (I_r = {fmt(spec['I_r'])} kg·m²)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    pwfig.save(fig, os.path.join(out, "sensitivity_K.png"))


KINDS = {f.__name__: f for f in (flat_com, friction_torque, stair, stair_progress, sweep_speed, sensitivity_K)}


def run(args):
    if len(args) < 2:
        raise pwfig.DataError("usage: paper.py OUT NAME... (draws OUT/data/NAME.json)")
    out, data = args[0], os.path.join(args[0], "data")
    for name in args[1:]:
        path = os.path.join(data, name + ".json")
        spec = pwfig.read_json(path)
        kind = pwfig.need(spec, "kind", path)
        if kind not in KINDS:
            raise pwfig.DataError(f"{path}: kind '{kind}' is not one of {', '.join(KINDS)}")
        try:
            KINDS[kind](out, data, spec)
        except KeyError as e:
            raise pwfig.DataError(f"{path}: no key {e}")


if __name__ == "__main__":
    pwfig.main(run)
