#!/usr/bin/python3
"""Figures of a pedalwave_runtime run (--plots DIR), from the data the runtime wrote there:

  cycles.csv, runtime.json -> runtime_signals.png (measured α, SEA torque, command u, wake latency)
                              observer.png (momentum residuals against the threshold, read time)
  body.csv, plant.json     -> snake_shapes.png, paths.png, speed.png (simulated plant only)

    /usr/bin/python3 tools/figures/runtime.py out/demo
"""
import os

import pwfig
from pwfig import np, plt


def runtime_figures(folder):
    cyc = pwfig.read_csv(os.path.join(folder, "cycles.csv"), required=("t_s", "wake_latency_us", "read_us",
                                                                       "alpha_1", "tau_sea_1", "u_1", "residual_1"))
    info = pwfig.read_json(os.path.join(folder, "runtime.json"))
    if len(cyc) < 2:
        print(f"{folder}/cycles.csv: {len(cyc)} rows, too few to plot")
        return
    t = cyc["t_s"]
    marks = [(m["t"], m["label"]) for m in info.get("marks") or []]

    fig, axes = pwfig.stacked("Runtime: joints, torques, loop timing", t, 4, panel_height=2.0, marks=marks)
    for name, label, ax, sym in (("alpha", "α [rad] (measured)", axes[0], "α"),
                                 ("tau_sea", "SEA torque τ_s [N·m]", axes[1], "τ_s,"),
                                 ("u", "command u [N·m]", axes[2], "u")):
        ys = cyc.numbered(name)
        for j, y in enumerate(ys):
            ax.plot(t, y, lw=1.2, label=f"{sym}{'' if sym.endswith(',') else '_'}{j + 1}")
        ax.set_ylabel(label)
        if name != "alpha" and pwfig.robust_ylim(ax, ys):
            ax.set_ylabel(label + "\n(start-up peaks off scale)")
    axes[3].plot(t, cyc["wake_latency_us"], lw=1.0, color=pwfig.CYCLE[0], label="wake latency")
    axes[3].set_ylabel("wake latency [µs]")
    pwfig.finish_stacked(fig, axes, os.path.join(folder, "runtime_signals.png"))

    fig, axes = pwfig.stacked("Observer: residuals, ± the threshold and its half (the persistence level)",
                              t, 2, panel_height=2.4, marks=marks)
    for j, y in enumerate(cyc.numbered("residual")):
        axes[0].plot(t, y, lw=1.2, label=f"r_{j + 1}")
    thr = info.get("residual_threshold")
    if thr is not None:
        for level, ls in ((thr, "--"), (thr / 2, ":")):
            for sign in (1, -1):
                axes[0].axhline(sign * level, color="#777", lw=1.1, ls=ls, zorder=1)
        axes[0].annotate(f"threshold ±{pwfig.fmt(thr)} N·m", (1.0, thr), xycoords=("axes fraction", "data"),
                         xytext=(-4, -11), textcoords="offset points", ha="right", fontsize=8, color="#555")
    axes[0].set_ylabel("momentum residual r [N·m]")
    axes[1].plot(t, cyc["read_us"], lw=1.0, color=pwfig.CYCLE[0], label="read")
    axes[1].set_ylabel("read [µs]")
    pwfig.finish_stacked(fig, axes, os.path.join(folder, "observer.png"))


def plant_figures(folder):
    body = pwfig.Body(os.path.join(folder, "body.csv"))
    plant = pwfig.read_json(os.path.join(folder, "plant.json"))
    scene = pwfig.need(plant, "scene", os.path.join(folder, "plant.json"))
    name = plant.get("name", "")
    pwfig.snake_shapes(os.path.join(folder, "snake_shapes.png"),
                       f"Snake shape, one snapshot per second ({name}, head tip = large dot)",
                       body, body.every(1.0), scene)
    pwfig.paths_xt(os.path.join(folder, "paths.png"), "COM and head tip paths", body.t,
                   [("COM", body.com_x, body.com_z), ("head tip", body.head_x, body.head_z)])

    # COM speed over a sliding 2 s window (one gait period at ω = π).
    t, x = body.t, body.com_x
    j = np.searchsorted(t, t - 2.0)
    dt = t - t[j]
    speed = np.where(dt > 0, 100.0 * (x - x[j]) / np.where(dt > 0, dt, 1.0), 0.0)
    fig, axes = pwfig.stacked(f"Forward speed ({name})", t, 1, panel_height=3.2)
    axes[0].plot(t, speed, label="COM, 2 s window")
    i0 = int(np.searchsorted(t, 2.0))  # the average the runtime prints: from t = 2 s on
    if i0 < len(t) - 1:
        avg = 100.0 * (x[-1] - x[i0]) / (t[-1] - t[i0])
        axes[0].axhline(avg, color=pwfig.RED, ls="--", lw=1.2,
                        label=f"average {avg:.3f} cm/s (t = {t[i0]:.1f} … {t[-1]:.1f} s)")
    axes[0].set_ylabel("COM speed [cm/s]")
    pwfig.finish_stacked(fig, axes, os.path.join(folder, "speed.png"))


def run(args):
    if len(args) != 1:
        raise pwfig.DataError("usage: runtime.py FOLDER (the folder of pedalwave_runtime --plots)")
    folder = args[0]
    runtime_figures(folder)
    if os.path.exists(os.path.join(folder, "body.csv")):
        plant_figures(folder)


if __name__ == "__main__":
    pwfig.main(run)
