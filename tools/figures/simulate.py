#!/usr/bin/python3
"""Figures of a pedalwave_sim run, from what it wrote into its output folder:

  body.csv, figures.json -> shapes.png      the body about every 10th of the run, colour = time (with
                                            the gait running: a whole number of gait cycles apart, the
                                            same phase of the wave, so what changes is the progress)
                            gait_cycle.png  the pedal wave over the last gait cycle (runs ≥ 1 cycle)
                            paths.png       head tip and COM in the x–z plane, start ○ end □
  trajectory.csv         -> torques.png     SEA torque and commanded torque, one panel per joint
                            speed.png       COM progress and forward speed

    /usr/bin/python3 tools/figures/simulate.py sim_out/stair
"""
import os

import pwfig
from pwfig import np, plt


def shapes(folder, body, info, scene, tail):
    t = body.t
    span = t[-1] - t[0]
    period = info.get("gait_period_s")
    spacing = span / 9.0 if span > 0 else 1.0
    same_phase = period is not None and span >= period
    if same_phase:
        spacing = period * max(1.0, round(spacing / period))
    idx = body.every(spacing)
    pwfig.snake_shapes(os.path.join(folder, "shapes.png"),
                       f"Body every {pwfig.fmt(spacing)} s{' (same gait phase)' if same_phase else ''}, "
                       f"head tip ● — {tail}", body, idx, scene)
    if same_phase:
        idx = body.at_times(t[-1] - period + period * np.arange(8) / 8)
        pwfig.snake_shapes(os.path.join(folder, "gait_cycle.png"),
                           f"The pedal wave over the last gait cycle ({pwfig.fmt(t[idx[0]])} … "
                           f"{pwfig.fmt(t[-1])} s), head tip ● — {tail}", body, idx, scene, time_legend=True)


def paths(folder, body, scene, tail):
    fig, ax = plt.subplots(figsize=(10, 5.2))
    x_hi = max(np.nanmax(body.head_x), np.nanmax(body.com_x))
    pwfig.draw_scene(ax, scene, x_hi)
    for (label, x, z), color in zip((("head tip", body.head_x, body.head_z), ("COM", body.com_x, body.com_z)),
                                    pwfig.CYCLE):
        ax.plot(x, z, color=color, label=label)
        ax.plot(x[:1], z[:1], "o", mfc="white", mec=color, ms=8, mew=1.5)
        ax.plot(x[-1:], z[-1:], "s", color=color, ms=7)
    zs = np.concatenate([body.head_z, body.com_z])
    lo, hi = np.nanmin(zs), np.nanmax(zs)
    ax.set_ylim(lo - 0.1 * (hi - lo) - 0.005, hi + 0.1 * (hi - lo) + 0.005)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(f"Head tip and COM paths (start ○, end □) — {tail}")
    ax.legend(loc="best")
    pwfig.save(fig, os.path.join(folder, "paths.png"))


def torques(folder, traj, tail):
    t = traj["t"]
    u = traj.numbered("u")
    tau = traj.numbered("tau_sea")
    if not u:
        raise pwfig.DataError(f"{traj.path}: no column 'u_1' (columns: {', '.join(traj.names)})")
    fig, axes = pwfig.stacked(f"Joint torques — {tail}", t, len(u), panel_height=1.35)
    clipped = False
    for j, ax in enumerate(axes):
        ys = [u[j]]
        if tau:
            ax.plot(t, tau[j], color=pwfig.CYCLE[0], lw=1.3, label="τ_sea (spring)")
            ys.append(tau[j])
        ax.plot(t, u[j], color=pwfig.RED, lw=1.1, ls="--", label="u (commanded)")
        ax.set_ylabel(f"joint {j + 1} [N·m]")
        clipped |= pwfig.robust_ylim(ax, ys)
    if clipped:
        fig.suptitle(f"Joint torques — {tail} (start-up peaks off scale)")
    # One legend: every panel has the same two lines.
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    fig.align_ylabels(axes)
    pwfig.save(fig, os.path.join(folder, "torques.png"))


def speed(folder, traj, info, tail):
    t, x, v = traj["t"], traj["com_x"], traj["v_forward"]
    fig, (ax, bx) = pwfig.stacked(f"Forward progress — {tail}", t, 2, panel_height=2.3)
    ax.plot(t, 100 * (x - x[0]), label="COM x")
    ax.set_ylabel("COM x − x₀ [cm]")
    bx.plot(t, 100 * v, color="#aaaaaa", lw=0.9, label="instantaneous")
    period = info.get("gait_period_s")
    if period is not None and len(t) > 1:
        w = int(round(period / (t[1] - t[0])))
        bx.plot(t, pwfig.moving_average(100 * v, w), color=pwfig.CYCLE[0], lw=2.0,
                label=f"mean over one gait cycle ({pwfig.fmt(period)} s)")
    avg = info.get("average_speed_m_s")
    if avg is not None:  # a failed run has no meaningful average speed
        bx.axhline(100 * avg, color=pwfig.RED, ls="--", label=f"average {pwfig.fmt(100 * avg)} cm/s")
    bx.set_ylabel("forward speed [cm/s]")
    pwfig.robust_ylim(bx, [100 * v])
    pwfig.finish_stacked(fig, [ax, bx], os.path.join(folder, "speed.png"))


def run(args):
    if len(args) != 1:
        raise pwfig.DataError("usage: simulate.py FOLDER (the --out folder of pedalwave_sim)")
    folder = args[0]
    info_path = os.path.join(folder, "figures.json")
    info = pwfig.read_json(info_path)
    scene = pwfig.need(info, "scene", info_path)
    tail = info.get("title", "")
    body = pwfig.Body(os.path.join(folder, "body.csv"))
    traj = pwfig.read_csv(os.path.join(folder, "trajectory.csv"), required=("t", "com_x", "v_forward"))
    shapes(folder, body, info, scene, tail)
    paths(folder, body, scene, tail)
    torques(folder, traj, tail)
    speed(folder, traj, info, tail)


if __name__ == "__main__":
    pwfig.main(run)
