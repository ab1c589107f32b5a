#!/usr/bin/python3
"""Figures of a pedalwave_monitor recording (--record PREFIX.csv writes PREFIX.<topic>.csv), as
pedalwave_plot_recording runs it (it writes OUT/body.csv, the body placed by the observer's pose):

  PREFIX.joint_state.csv (+ controller_state, observer_state) -> OUT/joint_signals.png
  PREFIX.loop_timing.csv                                       -> OUT/loop_timing.png
  OUT/body.csv                                                 -> OUT/snake_shapes.png, OUT/paths.png

Each topic is drawn on its own time stamps (stamp_ns, from the joint samples' first). Joint
columns are 1-based, as the legends (alpha_1 is α_1).

    /usr/bin/python3 tools/figures/recording.py run out/recording [--every 1.0]
"""
import os

import pwfig


def topic(base, name, required):
    path = f"{base}.{name}.csv"
    if not os.path.exists(path):
        if required:
            raise pwfig.DataError(f"{path}: not there (record with pedalwave_monitor --record PREFIX.csv)")
        return None
    tab = pwfig.read_csv(path, required=("stamp_ns",), skip_ragged=True)
    return tab if len(tab) else None


def run(args):
    if len(args) not in (2, 4) or (len(args) == 4 and args[2] != "--every"):
        raise pwfig.DataError("usage: recording.py PREFIX OUT [--every SECONDS]")
    base, out = args[0], args[1]
    every = float(args[3]) if len(args) == 4 else 1.0
    js = topic(base, "joint_state", True)
    if js is None or len(js) < 2:
        raise pwfig.DataError(f"{base}.joint_state.csv: fewer than 2 samples")
    cs, obs, lt = (topic(base, n, False) for n in ("controller_state", "observer_state", "loop_timing"))
    t0 = js["stamp_ns"][0]
    t = (js["stamp_ns"] - t0) * 1e-9

    panels = [(js, "alpha", "α [rad] (measured)", "α"), (cs, "alpha_d", "α^d [rad]", "α^d"),
              (js, "tau_sea", "SEA torque τ_s [N·m]", "τ_s"), (cs, "u", "command u [N·m]", "u"),
              (obs, "residual", "residual r [N·m]", "r")]
    panels = [p for p in panels if p[0] is not None and p[0].numbered(p[1])]
    fig, axes = pwfig.stacked(f"Recorded joint signals ({base})", t, len(panels), panel_height=1.8)
    for ax, (tab, field, label, sym) in zip(axes, panels):
        tt = (tab["stamp_ns"] - t0) * 1e-9
        for j, y in enumerate(tab.numbered(field)):
            ax.plot(tt, y, lw=1.2, label=f"{sym}_{j + 1}")
        ax.set_ylabel(label)
    pwfig.finish_stacked(fig, axes, os.path.join(out, "joint_signals.png"))

    if lt is not None and "wake_latency_ns" in lt:
        tl = (lt["stamp_ns"] - t0) * 1e-9
        fig, axes = pwfig.stacked("Loop timing", tl, 1, panel_height=2.6)
        axes[0].plot(tl, lt["wake_latency_ns"] * 1e-3, lw=1.0, label="wake latency")
        axes[0].set_ylabel("wake latency [µs]")
        pwfig.finish_stacked(fig, axes, os.path.join(out, "loop_timing.png"))

    body_csv = os.path.join(out, "body.csv")
    if os.path.exists(body_csv):
        body = pwfig.Body(body_csv)
        pwfig.snake_shapes(os.path.join(out, "snake_shapes.png"),
                           "Snake shape (measured α, predicted body pose)", body, body.every(every),
                           {"ground_z": None})
        pwfig.paths_xt(os.path.join(out, "paths.png"), "COM path (predicted)", body.t,
                       [("COM (predicted)", body.com_x, body.com_z)])


if __name__ == "__main__":
    pwfig.main(run)
