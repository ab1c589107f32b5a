#!/usr/bin/env python3
"""Checks a pedalwave_runtime --report-json file against the report schema (tools/runtime/run_report.hpp).

Usage: check_run_report.py REPORT.json   — exit 0 and "ok" when every key is there with its type.
"driver" is the bus kind, "driver_counters" its counters.
"""
import json
import sys

NUM = (int, float)


def pairs_hook(pairs):
    d = {}
    for k, v in pairs:
        if k in d:
            raise SystemExit(f"duplicate key {k!r}")
        d[k] = v
    return d


def need(obj, key, types, where):
    if key not in obj:
        raise SystemExit(f"{where}: missing key {key!r}")
    v = obj[key]
    if isinstance(v, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise SystemExit(f"{where}.{key}: bool, expected {types}")
    if not isinstance(v, types):
        raise SystemExit(f"{where}.{key} = {v!r}: expected {types}")
    return v


def main(path):
    with open(path, encoding="utf-8") as f:
        r = json.load(f, object_pairs_hook=pairs_hook)
    need(r, "name", str, "report")
    need(r, "config", str, "report")
    if need(r, "driver", str, "report") not in ("sim", "socketcan", "serial"):
        raise SystemExit(f"report.driver = {r['driver']!r}")
    need(r, "rate_hz", NUM, "report")
    need(r, "duration_s", NUM, "report")
    ex = need(r, "exit", dict, "report")
    for k in ("reason", "final_mode", "fault"):
        need(ex, k, str, "exit")
    need(ex, "joint", (int, type(None)), "exit")
    need(ex, "signal", int, "exit")
    for i, e in enumerate(need(r, "events", list, "report")):
        w = f"events[{i}]"
        need(e, "t", NUM, w)
        need(e, "cycle", int, w)
        if need(e, "kind", str, w) not in ("fault", "warning", "mode", "operator"):
            raise SystemExit(f"{w}.kind = {e['kind']!r}")
        need(e, "class", str, w)
        need(e, "severity", str, w)
        j = need(e, "joint", (int, type(None)), w)
        if j is not None and j < 1:
            raise SystemExit(f"{w}.joint = {j}: expected 1-based")
        need(e, "value", (int, float, type(None)), w)  # null: not finite (a NaN command)
        need(e, "threshold", (int, float, type(None)), w)
        need(e, "text", str, w)
        if need(e, "reaction", str, w) not in ("continue", "hold", "safe_stop", "none"):
            raise SystemExit(f"{w}.reaction = {e['reaction']!r}")
    need(r, "events_dropped", int, "report")
    loop = need(r, "loop", dict, "report")
    for k in ("cycles", "overruns", "skipped_periods", "max_skipped", "cycle_drops", "event_drops"):
        need(loop, k, int, "loop")
    timing = need(r, "timing_us", dict, "report")
    for h in ("wake", "read", "observe", "control", "write", "cycle"):
        t = need(timing, h, dict, "timing_us")
        need(t, "count", int, h)
        for k in ("min", "p50", "p90", "p99", "p999", "max"):
            need(t, k, NUM, h)
        need(t, "overflows", int, h)
        total = 0
        for b in need(t, "bins", list, h):
            if len(b) != 3 or not all(isinstance(x, NUM) for x in b) or b[2] <= 0 or b[0] > b[1]:
                raise SystemExit(f"{h}.bins: bad bin {b!r}")
            total += b[2]
        if total != t["count"]:
            raise SystemExit(f"{h}.bins: counts sum to {total}, count = {t['count']}")
    counters = need(r, "driver_counters", dict, "report")
    for k in ("frames_tx", "frames_rx", "missing", "late", "duplicate", "out_of_order", "checksum",
              "malformed", "bus_errors", "tx_dropped", "rx_dropped"):
        need(counters, k, int, "driver")
    if need(counters, "rx_silence_max_s", NUM, "driver") < 0:
        raise SystemExit("driver_counters.rx_silence_max_s: negative")
    s = need(r, "settings", dict, "report")
    need(s, "stale_timeout_s", NUM, "settings")
    need(s, "read_budget", NUM, "settings")
    need(s, "observer", bool, "settings")
    need(s, "telemetry", bool, "settings")
    print("ok")


if __name__ == "__main__":
    main(sys.argv[1])
