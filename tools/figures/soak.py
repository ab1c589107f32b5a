#!/usr/bin/python3
"""Figures of a soak run (pedalwave_soak's soak.json): the timing histograms of the runtime's
report (wake latency, read, observe, control; log count) and the memory of the runtime and the
virtual robot over time (VmRSS, VmHWM).

    /usr/bin/python3 tools/figures/soak.py out/soak/soak.json out/soak/soak.png

Without matplotlib pwfig says so and exits 3 (pedalwave_soak: "figures skipped")."""
import pwfig
from pwfig import plt

STAGES = ["wake", "read", "observe", "control"]


def main(soak_json, png):
    soak = pwfig.read_json(soak_json)
    report = soak.get("report") or {}
    timing = report.get("timing_us") or {}
    stages = [s for s in STAGES if (timing.get(s) or {}).get("bins")]
    memory = soak.get("memory") or {}

    # Top row: one histogram per stage; bottom row: memory over the whole width.
    cols = max(1, len(stages))
    fig = plt.figure(figsize=(4.0 * max(cols, 2), 7.0))
    grid = fig.add_gridspec(2, cols)
    for k, name in enumerate(stages):
        ax = fig.add_subplot(grid[0, k])
        s = timing[name]
        lo = [b[0] for b in s["bins"]]
        width = [b[1] - b[0] for b in s["bins"]]
        count = [b[2] for b in s["bins"]]
        # The histogram's last bin is an overflow bin (e.g. 5 ms … the maximum): drawn hatched, so
        # its width is not read as weight.
        wide = len(lo) > 1 and s["bins"][-1][1] > 2 * s["bins"][-1][0]
        n = len(lo) - 1 if wide else len(lo)
        ax.bar(lo[:n], count[:n], width=width[:n], align="edge", color="tab:blue", edgecolor="none")
        if wide:
            ax.bar(lo[-1:], count[-1:], width=width[-1:], align="edge", facecolor="none",
                   edgecolor="tab:blue", hatch="//", label="%d in %g … %g" % (count[-1], lo[-1], lo[-1] + width[-1]))
        ax.set_yscale("log")
        # Log time axis: the bulk (tens of µs) and the rare 100 ms outliers in one view.
        ax.set_xscale("log")
        rate = report.get("rate_hz")
        if isinstance(rate, (int, float)) and rate > 0:
            ax.axvline(1e6 / rate, color="tab:red", ls="--", lw=1, label="period")
        ax.legend(fontsize=7)
        ax.set_xlabel(name + " [µs]")
        ax.set_ylabel("cycles")
        ax.set_title("%s: p50 %s, p99 %s, max %s µs" % (name, s.get("p50"), s.get("p99"), s.get("max")), fontsize=9)
        used = [b for b in s["bins"] if b[2] > 0]
        if used:
            ax.set_xlim(max(used[0][0], 0.1), max(used[-1][1], 1e6 / rate if isinstance(rate, (int, float)) and rate > 0 else 0) * 1.2)

    ax = fig.add_subplot(grid[1, :])
    for proc, color in (("runtime", "tab:red"), ("virtual_robot", "tab:green")):
        rows = memory.get(proc) or []
        if not rows:
            continue
        t = [r["t_s"] for r in rows]
        ax.plot(t, [r["rss_kB"] / 1024 for r in rows], "-o", ms=3, color=color, label=proc + " RSS")
        ax.plot(t, [r["hwm_kB"] / 1024 for r in rows], "--", color=color, label=proc + " peak")
    ax.set_xlabel("time since the runtime started [s]")
    ax.set_ylabel("memory [MB]")
    ax.set_ylim(bottom=0)
    ax.set_title("memory (/proc/<pid>/status)", fontsize=9)
    ax.legend(fontsize=7)
    settings = soak.get("settings") or {}
    load = soak.get("load") or {}
    fig.suptitle("soak %s s, load %s × %s, telemetry %s" % (settings.get("duration_s"), load.get("children"),
                                                          load.get("duty"), settings.get("telemetry")), fontsize=10)
    fig.tight_layout()
    pwfig.save(fig, png)


def run(args):
    if len(args) != 2:
        raise pwfig.DataError("usage: soak.py SOAK_JSON PNG")
    main(args[0], args[1])


if __name__ == "__main__":
    pwfig.main(run)
