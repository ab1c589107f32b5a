#!/usr/bin/python3
"""Work-precision figures of pedalwave_workprec, from its work_precision.csv: per scene,
<scene>_com.png (max COM position error against the run's CPU time, the 1 mm line) and
<scene>_alpha.png (max joint-angle error), log–log, one line per integrator; runs that were not ok
(unstable, failed) are left out.

    /usr/bin/python3 tools/figures/workprec.py tools/workprec/results
"""
import os
import re

import pwfig
from pwfig import np, plt

LABELS = {"euler": "explicit Euler", "semi_implicit_euler": "semi-implicit Euler",
          "implicit_velocity": "implicit velocity", "rk4": "RK4", "dopri45": "dopri45",
          "implicit_contact": "implicit contact"}
MARKERS = ["o", "s", "^", "D", "v", "P", "X"]


def ids(table, what):
    """The 'scene ids: 0=free_fall 1=...' comment as {0: "free_fall", ...}."""
    for c in table.comments:
        if c.startswith(what + " ids:"):
            return {int(k): v for k, v in re.findall(r"(\d+)=(\S+)", c)}
    raise pwfig.DataError(f"{table.path}: no '# {what} ids: ...' comment line")


def run(args):
    if len(args) != 1:
        raise pwfig.DataError("usage: workprec.py FOLDER (the --out folder of pedalwave_workprec)")
    folder = args[0]
    tab = pwfig.read_csv(os.path.join(folder, "work_precision.csv"),
                         required=("scene", "method", "status", "cpu_s", "com_err_max_m", "alpha_err_max_rad"))
    scenes, methods = ids(tab, "scene"), ids(tab, "method")
    duration = next((m.group(1) for c in tab.comments for m in [re.search(r"duration (\S+) s", c)] if m), "?")
    ok = tab["status"] == 0
    for s_id, scene in scenes.items():
        for column, suffix, ylabel, what in (
                ("com_err_max_m", "com", "max COM position error [m]", "max COM error"),
                ("alpha_err_max_rad", "alpha", "max joint angle error [rad]", "max joint-angle error")):
            fig, ax = plt.subplots(figsize=(10, 6))
            drawn = False
            for k, (m_id, method) in enumerate(methods.items()):
                sel = ok & (tab["scene"] == s_id) & (tab["method"] == m_id) & (tab[column] > 0)
                if not sel.any():
                    continue
                order = np.argsort(tab["cpu_s"][sel])
                ax.plot(tab["cpu_s"][sel][order], tab[column][sel][order], marker=MARKERS[k % len(MARKERS)],
                        ms=6, label=LABELS.get(method, method))
                drawn = True
            if not drawn:
                plt.close(fig)
                continue
            if suffix == "com":
                ax.axhline(1e-3, color=pwfig.RED, ls="--", lw=1.2)
                ax.annotate("1 mm", (1.0, 1e-3), xycoords=("axes fraction", "data"), xytext=(-4, 3),
                            textcoords="offset points", ha="right", fontsize=9, color=pwfig.RED)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="minor", color="#f0f0f0", lw=0.6)
            pwfig.plain_log_ticks(ax.xaxis)
            ax.set_xlabel(f"CPU time of the run [s] ({duration} s simulated)")
            ax.set_ylabel(ylabel)
            ax.set_title(f"{scene}: {what} vs CPU time (unstable runs omitted)")
            ax.legend(loc="best")
            pwfig.save(fig, os.path.join(folder, f"{scene}_{suffix}.png"))


if __name__ == "__main__":
    pwfig.main(run)
