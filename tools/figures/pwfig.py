"""Shared pieces of pedalwave's figure scripts: the style, reading the tools' CSV and JSON with
errors that name the file and the column, and the drawings several tools use (the snake's body
over time with the ground, boxes and friction patches; stacked time series; paths).

Every script imports this module first. Without numpy or matplotlib it prints why and exits 3
(the tools then say "figures skipped"); bad data exit 2 with the file and the column named.
"""
import csv
import json
import math
import os
import sys

try:
    import numpy as np
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colors as mcolors
    from matplotlib.lines import Line2D
    from mpl_toolkits.axes_grid1 import make_axes_locatable
except ImportError as e:
    print(f"figures skipped: {sys.executable} cannot import {e.name} "
          "(Debian: apt-get install python3-matplotlib python3-numpy)")
    sys.exit(3)

# Okabe–Ito: a colour cycle people with colour-vision deficiencies can tell apart.
CYCLE = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000"]
RED = "#C81E1E"
GROUND, GROUND_FILL = "#6E553C", "#E8DDCF"
BOX_FILL, BOX_EDGE = "#A07850", "#5A3C1E"
MU_FILL = "#4682C8"
DPI = 100  # figure sizes below are in inches: 10 in = 1000 px

plt.rcParams.update({
    "figure.facecolor": "white",
    "axes.prop_cycle": matplotlib.cycler(color=CYCLE),
    "axes.grid": True,
    "grid.color": "#dddddd",
    "grid.linewidth": 0.8,
    "axes.titleweight": "bold",
    "figure.titleweight": "bold",
    "figure.titlesize": 13,
    "axes.titlesize": 11,
    "font.size": 10,
    "legend.fontsize": 9,
    "legend.framealpha": 0.9,
    "lines.linewidth": 1.5,
    "savefig.dpi": DPI,
})


class DataError(Exception):
    """Bad input data: the message names the file and what is wrong."""


def main(fn):
    """Runs fn(sys.argv[1:]); a DataError becomes one line on stderr and exit status 2."""
    try:
        fn(sys.argv[1:])
    except DataError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    if WRITTEN:
        folder = os.path.dirname(WRITTEN[0])
        if len(WRITTEN) == 1:
            print(f"wrote {WRITTEN[0]}")
        elif all(os.path.dirname(p) == folder for p in WRITTEN):
            print(f"wrote {os.path.join(folder, '')}{{{','.join(os.path.basename(p) for p in WRITTEN)}}}")
        else:
            print("wrote " + ", ".join(WRITTEN))


class Table:
    """A CSV read by column: table["t"] is a numpy array. Text cells (e.g. a mode name) are NaN."""

    def __init__(self, path, names, rows, comments):
        self.path, self.names, self.comments = path, names, comments
        data = np.full((len(rows), len(names)), np.nan)
        for i, r in enumerate(rows):
            for k, cell in enumerate(r):
                try:
                    data[i, k] = float(cell)
                except ValueError:
                    pass
        self.cols = {n: data[:, k] for k, n in enumerate(names)}
        self.text = {n: [r[k] for r in rows] for k, n in enumerate(names)}

    def __len__(self):
        return len(next(iter(self.cols.values()))) if self.cols else 0

    def __contains__(self, name):
        return name in self.cols

    def __getitem__(self, name):
        if name not in self.cols:
            raise DataError(f"{self.path}: no column '{name}' (columns: {', '.join(self.names)})")
        return self.cols[name]

    def numbered(self, prefix, first=1):
        """Columns prefix_1, prefix_2, ... (or from `first`) as long as they exist."""
        out, k = [], first
        while f"{prefix}_{k}" in self.cols:
            out.append(self.cols[f"{prefix}_{k}"])
            k += 1
        return out


def read_csv(path, required=(), skip_ragged=False):
    """Reads a tool's CSV: '#' comment lines, one header line, rows. Raises DataError naming the
    file (and the line, or the missing column of `required`). skip_ragged: a row with the wrong
    number of cells (a recording cut short while written) is skipped with a note instead."""
    try:
        with open(path, newline="") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise DataError(f"{path}: cannot read ({e.strerror})")
    comments, body = [], []
    for line in lines:
        if line.startswith("#"):
            comments.append(line[1:].strip())
        elif line.strip():
            body.append(line)
    if not body:
        raise DataError(f"{path}: no header line (empty file?)")
    parsed = list(csv.reader(body))
    names, rows = parsed[0], []
    for i, r in enumerate(parsed[1:]):
        if len(r) != len(names):
            what = f"{path}: data row {i + 1} has {len(r)} values but the header names {len(names)} columns"
            if not skip_ragged:
                raise DataError(what)
            print(what + ": row skipped")
            continue
        rows.append(r)
    table = Table(path, names, rows, comments)
    for name in required:
        table[name]  # raises naming the file and the column
    return table


def read_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as e:
        raise DataError(f"{path}: cannot read ({e.strerror})")
    except json.JSONDecodeError as e:
        raise DataError(f"{path}: not JSON ({e.msg}, line {e.lineno})")


def need(obj, key, source):
    """obj[key], or a DataError naming the source file and the key."""
    if key not in obj:
        raise DataError(f"{source}: no key '{key}'")
    return obj[key]


WRITTEN = []


def save(fig, path):
    """Writes the figure as PNG; main() lists what was written (the tools pass it on to the user)."""
    fig.savefig(path, dpi=DPI, bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)
    WRITTEN.append(path)


def fmt(v, digits=3):
    """A number with `digits` significant digits, no trailing zeros ("0.351", "10.1", "2")."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return f"{v:.{digits}g}"


# ---- The body and the scene ----------------------------------------------------------------------


class Body:
    """A body.csv: per sample t, the COM and head tip, and the 2N+1 body points from the tail tip
    to the head tip (x_0..x_2N, z_0..z_2N; even indices are the tips and joints)."""

    def __init__(self, path):
        tab = read_csv(path, required=("t", "com_x", "com_z", "head_x", "head_z", "x_0", "z_0"))
        self.path = path
        self.t = tab["t"]
        self.com_x, self.com_z = tab["com_x"], tab["com_z"]
        self.head_x, self.head_z = tab["head_x"], tab["head_z"]
        self.x = np.column_stack(tab.numbered("x", 0))
        self.z = np.column_stack(tab.numbered("z", 0))
        if self.x.shape != self.z.shape:
            raise DataError(f"{path}: {self.x.shape[1]} x_k columns but {self.z.shape[1]} z_k columns")
        if len(self.t) < 1:
            raise DataError(f"{path}: no rows")

    def at_times(self, times):
        """Sample indices nearest to each of `times` (sorted, unique)."""
        idx = np.clip(np.searchsorted(self.t, times), 0, len(self.t) - 1)
        return sorted(set(int(i) for i in idx))

    def every(self, period, t_hi=None):
        """Indices about every `period` seconds from the first sample (up to t_hi)."""
        t_hi = self.t[-1] if t_hi is None else t_hi
        return self.at_times(np.arange(self.t[0], t_hi + 1e-9, period))


def draw_scene(ax, scene, x_hi, legend=True):
    """Ground (line and a shaded strip below), the boxes and the friction patches (strips just
    under the ground line, the last one up to x_hi) of a scene dict: {"ground_z": z or null,
    "boxes": [{"x0", "x1", "z0", "z1"}], "patches": [{"x_begin", "mu"}]}."""
    gz = scene.get("ground_z")
    if gz is None:
        return
    ax.axhline(gz, color=GROUND, lw=1.2, zorder=1)
    ax.axhspan(gz - 1.0, gz, color=GROUND_FILL, lw=0, zorder=0)
    patches = scene.get("patches") or []
    for i, p in enumerate(patches):
        x1 = patches[i + 1]["x_begin"] if i + 1 < len(patches) else max(x_hi, p["x_begin"] + 0.05)
        ax.fill_between([p["x_begin"], x1], gz - 0.012, gz, color=MU_FILL, alpha=0.55, lw=0, zorder=1,
                        label=f"μ = {fmt(p['mu'], 2)} from x = {fmt(p['x_begin'], 2)} m" if legend else None)
    for i, b in enumerate(scene.get("boxes") or []):
        ax.add_patch(matplotlib.patches.Rectangle(
            (b["x0"], b["z0"]), b["x1"] - b["x0"], b["z1"] - b["z0"], facecolor=BOX_FILL, alpha=0.5,
            edgecolor=BOX_EDGE, zorder=1,
            label=f"box {fmt((b['x1'] - b['x0']) * 100)} × {fmt((b['z1'] - b['z0']) * 100)} cm"
            if legend and i == 0 else None))


def draw_body(ax, x, z, color, head=True, lw=1.8, joints=True):
    """One body: a polyline, the tips and joints marked, the head tip as a larger dot."""
    ax.plot(x, z, color=color, lw=lw, zorder=3, solid_capstyle="round")
    if joints:
        ax.plot(x[::2], z[::2], "o", ms=3.5, color=color, mec="white", mew=0.5, zorder=4)
    if head:
        ax.plot(x[-1:], z[-1:], "o", ms=7.5, color=color, mec="white", mew=0.7, zorder=5)


def snake_shapes(path, title, body, indices, scene, time_legend=False):
    """The body at the samples `indices`, colour = time (viridis, with a colour bar), true aspect,
    with the scene; the legend (boxes, patches, markers) outside on the right."""
    xs, zs = body.x[indices], body.z[indices]
    x_lo, x_hi = np.nanmin(xs), np.nanmax(xs)
    z_lo, z_hi = np.nanmin(zs), np.nanmax(zs)
    gz = scene.get("ground_z")
    if gz is not None:
        z_lo = min(z_lo, gz - 0.02)
    for b in scene.get("boxes") or []:
        x_hi, z_hi = max(x_hi, b["x1"]), max(z_hi, b["z1"])
    pad_x, pad_z = 0.04 * (x_hi - x_lo) + 0.01, 0.08 * (z_hi - z_lo) + 0.01
    width = 10.0
    aspect = (z_hi - z_lo + 2 * pad_z) / (x_hi - x_lo + 2 * pad_x)
    fig, ax = plt.subplots(figsize=(width, min(max(width * 0.75 * aspect + 1.3, 3.2), 9.0)))
    draw_scene(ax, scene, x_hi)
    times = body.t[indices]
    norm = mcolors.Normalize(vmin=times.min(), vmax=max(times.max(), times.min() + 1e-9))
    cmap = plt.get_cmap("viridis")
    for i, t in zip(indices, times):
        draw_body(ax, body.x[i], body.z[i], cmap(norm(t)))
        if time_legend:
            ax.plot([], [], color=cmap(norm(t)), label=f"t = {fmt(t)} s")
    ax.set_xlim(x_lo - pad_x, x_hi + pad_x)
    ax.set_ylim(z_lo - pad_z, z_hi + pad_z)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(title)
    legend_right_of = ax
    if not time_legend:  # a colour bar as tall as the panel, right beside it
        cax = make_axes_locatable(ax).append_axes("right", size="2.5%", pad=0.12)
        bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax)
        bar.set_label("time [s]")
        legend_right_of = cax
    handles, labels = ax.get_legend_handles_labels()
    handles += [Line2D([], [], ls="", marker="o", ms=3.5, color="#444"),
                Line2D([], [], ls="", marker="o", ms=7.5, color="#444")]
    labels += ["joints / tips", "head tip"]
    outside_right_legend(fig, ax, legend_right_of, handles, labels)
    save(fig, path)


def outside_right_legend(fig, ax, right_of, handles, labels):
    """A legend whose top left corner is at the top of `ax`, right of `right_of` (the panel or its
    colour bar, tick labels included): it never covers data."""
    fig.canvas.draw()
    box = right_of.get_tightbbox(fig.canvas.get_renderer()).transformed(fig.transFigure.inverted())
    top = ax.get_position().y1
    fig.legend(handles, labels, loc="upper left", bbox_to_anchor=(box.x1 + 0.01, top), borderaxespad=0)


def body_film(path, title, body, indices, scene, cols=3):
    """A film strip: one panel per sample of `indices`, the same axes limits in every panel."""
    rows = math.ceil(len(indices) / cols)
    boxes = scene.get("boxes") or []
    x_lo = np.nanmin(body.x) - 0.02
    x_hi = max([np.nanmax(body.x)] + [b["x1"] for b in boxes]) + 0.02
    z_lo = min(np.nanmin(body.z), scene.get("ground_z") or 0.0) - 0.02
    z_hi = max([np.nanmax(body.z)] + [b["z1"] for b in boxes]) + 0.02
    panel_w = 0.8 * 12.0 / cols  # the plot box: the figure's width less the margins and gaps
    panel_h = max(panel_w * (z_hi - z_lo) / (x_hi - x_lo), 1.0) + 0.6  # the panel's title and ticks
    fig, axes = plt.subplots(rows, cols, figsize=(12, panel_h * rows + 0.9), sharex=True, sharey=True,
                             squeeze=False)
    fig.subplots_adjust(top=1 - 0.6 / (panel_h * rows + 0.9), hspace=0.35, wspace=0.08)
    for k, ax in enumerate(axes.flat):
        if k >= len(indices):
            ax.axis("off")
            continue
        i = indices[k]
        draw_scene(ax, scene, x_hi, legend=False)
        draw_body(ax, body.x[i], body.z[i], CYCLE[0], lw=2.5, joints=False)
        ax.plot(body.x[i][-1:], body.z[i][-1:], "o", color=RED, ms=6, zorder=6)
        ax.set_title(f"t = {fmt(body.t[i])} s", fontweight="normal")
        ax.set_xlim(x_lo, x_hi)
        ax.set_ylim(z_lo, z_hi)
        ax.set_aspect("equal", adjustable="box")
    for ax in axes[-1]:
        ax.set_xlabel("x [m]")
    for ax in axes[:, 0]:
        ax.set_ylabel("z [m]")
    fig.suptitle(title)
    save(fig, path)


# ---- Time series -----------------------------------------------------------------------------------


def robust_ylim(ax, ys):
    """Limits the panel to the 0.5 … 99.5 % quantiles of its samples (padded) when the full range
    is much wider: a start-up transient would flatten everything else. Returns whether it did."""
    v = np.concatenate([np.asarray(y, float).ravel() for y in ys])
    v = v[np.isfinite(v)]
    if v.size < 20:
        return False
    lo, hi = np.quantile(v, [0.005, 0.995])
    span = max(hi - lo, 1e-9)
    if v.min() >= lo - 0.5 * span and v.max() <= hi + 0.5 * span:
        return False
    ax.set_ylim(lo - 0.15 * span, hi + 0.15 * span)
    return True


def stacked(title, t, n_panels, panel_height=1.9, width=10.0, marks=()):
    """A figure of n_panels panels stacked over a shared time axis (no margin at the ends), with the
    marks [(t, label)] as vertical lines in every panel (labelled in the top one). Returns
    (fig, axes); finish with finish_stacked."""
    height = panel_height * n_panels + 0.9
    fig, axes = plt.subplots(n_panels, 1, figsize=(width, height), sharex=True, squeeze=False)
    fig.subplots_adjust(top=1 - 0.5 / height, bottom=0.55 / height, hspace=0.22)
    axes = list(axes[:, 0])
    for ax in axes:
        ax.margins(x=0)
        for tm, _ in marks:
            ax.axvline(tm, color=RED, lw=1.0, ls="--", zorder=1)
    for tm, label in marks:
        axes[0].annotate(label, (tm, 1.0), xycoords=("data", "axes fraction"), xytext=(2, 2),
                         textcoords="offset points", fontsize=8, color=RED, rotation=0)
    axes[-1].set_xlabel("time [s]")
    if len(t):
        axes[-1].set_xlim(t[0], t[-1])
    fig.suptitle(title)
    return fig, axes


def finish_stacked(fig, axes, path):
    """Legends outside on the right of every panel that has labelled lines, then save."""
    for ax in axes:
        if ax.get_legend_handles_labels()[1]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    fig.align_ylabels(axes)
    save(fig, path)


def moving_average(y, w):
    """Centred moving average over w samples (shorter at the ends)."""
    y = np.asarray(y, float)
    if w < 2 or y.size == 0:
        return y
    h = w // 2
    c = np.concatenate([[0.0], np.cumsum(y)])
    i = np.arange(y.size)
    lo, hi = np.maximum(i - h, 0), np.minimum(i + h + 1, y.size)
    return (c[hi] - c[lo]) / (hi - lo)


def paths_xt(path, title, t, traces):
    """x(t) above z(t) for the traces [(label, x, z)]."""
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    fig.subplots_adjust(top=0.92, hspace=0.15)
    for label, x, z in traces:
        ax.plot(t, x, label=label)
        bx.plot(t, z, label=label)
    ax.set_ylabel("x [m]")
    bx.set_ylabel("z [m]")
    bx.set_xlabel("time [s]")
    ax.margins(x=0)
    ax.legend(loc="best")
    fig.suptitle(title)
    fig.align_ylabels([ax, bx])
    save(fig, path)


def plain_log_ticks(axis):
    """Decimal tick labels (0.05, 0.1, 0.2) on a log axis spanning less than 3 decades, where
    10⁻¹-style labels leave too few numbers to read values off."""
    lo, hi = axis.get_view_interval()
    if lo <= 0 or hi / lo >= 1e3:
        return
    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    labelled = (2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0) if hi / lo < 10 else (2.0, 5.0)  # < 1 decade: all
    axis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
        lambda v, _: f"{v:g}" if round(v / 10 ** math.floor(math.log10(v) + 1e-9), 6) in labelled else ""))
