// Shared by foxglove_client.mjs and check_mcap.mjs: the CSV recording of the same run as the
// reference, decoded messages in plain JSON terms, and the comparisons.
import { readFileSync, existsSync } from "node:fs";

export function fail(what) {
  console.error(`FAILED: ${what}`);
  process.exit(1);
}
export function check(cond, what) {
  if (!cond) fail(what);
}

// Decoded values in JSON terms: typed arrays as arrays, int64 (BigInt) as decimal strings.
export function normalize(v) {
  if (typeof v === "bigint") return v.toString();
  if (ArrayBuffer.isView(v)) return Array.from(v, normalize);
  if (Array.isArray(v)) return v.map(normalize);
  if (v !== null && typeof v === "object") {
    const o = {};
    for (const [k, x] of Object.entries(v)) o[k] = normalize(x);
    return o;
  }
  return v;
}

// The CSV recorder's topics → the ROS topic of robot "demo", the key that pairs a message with
// its row, and whether every row must be found (reliable topics) or most (best-effort).
export const CSV_TOPICS = {
  joint_state: { topic: "/demo/pedalwave/joint_state", key: "seq", all: false },
  controller_state: { topic: "/demo/pedalwave/controller_state", key: "seq", all: false },
  observer_state: { topic: "/demo/pedalwave/observer_state", key: "seq", all: false },
  loop_timing: { topic: "/demo/pedalwave/loop_timing", key: "seq", all: false },
  mode_event: { topic: "/demo/pedalwave/mode_event", key: "event_seq", all: true },
  fault_event: { topic: "/demo/pedalwave/fault_event", key: "event_seq", all: true },
  robot_description: { topic: "/demo/pedalwave/robot_description", key: null, all: true },
};

function parseCsvLine(line) {
  const out = [];
  let i = 0;
  while (i <= line.length) {
    if (line[i] === '"') {
      let s = "";
      ++i;
      for (;;) {
        if (line[i] === '"' && line[i + 1] === '"') { s += '"'; i += 2; }
        else if (line[i] === '"') { ++i; break; }
        else s += line[i++];
      }
      out.push(s);
      ++i;  // the comma
    } else {
      const j = line.indexOf(",", i);
      const end = j < 0 ? line.length : j;
      out.push(line.slice(i, end));
      i = end + 1;
    }
  }
  return out;
}

// rows of run.<topic>.csv as {column: text}, by the topic's key ("" for the description).
export function loadCsv(stem, name) {
  const path = `${stem}.${name}.csv`;
  check(existsSync(path), `${path} missing`);
  const lines = readFileSync(path, "utf8").split("\n").filter((l) => l.length > 0);
  if (lines.length === 0) return { header: [], rows: new Map(), path };
  const header = parseCsvLine(lines[0]);
  const rows = new Map();
  for (const l of lines.slice(1)) {
    const cells = parseCsvLine(l);
    check(cells.length === header.length, `${path}: a row with ${cells.length} cells, header ${header.length}`);
    const row = Object.fromEntries(header.map((h, i) => [h, cells[i]]));
    const key = CSV_TOPICS[name].key ? row[CSV_TOPICS[name].key] : "";
    rows.set(key, row);
  }
  return { header, rows, path };
}

// A decoded message against its CSV row: every column (but the receiver's recv_ns and
// source_time_ns) is a field, or element k−1 of an array field for `<field>_<k>` (the joint
// columns are 1-based: alpha_1 is alpha[0]); numbers equal
// exactly (the CSV holds shortest round-trip doubles), int64 and strings as text; arrays exactly
// as long as the row's columns for them.
// CSV columns named otherwise than the message's fields (recorder.cpp).
const ALIASES = {
  theta_N: ["body", 0], p_x: ["body", 1], p_z: ["body", 2],
  theta_N_dot: ["body", 3], p_x_dot: ["body", 4], p_z_dot: ["body", 5],
  from: ["from_mode"], to: ["to_mode"],
};
// Columns the CSV recorder derives: fault_names = the names of fault_flags' bits (compared as flags).
const DERIVED = new Set(["recv_ns", "source_time_ns", "fault_names"]);

export function compareToRow(msg, row, header, where) {
  const arrayColumns = new Map();
  for (const col of header) {
    if (DERIVED.has(col)) continue;
    let value;
    if (Object.hasOwn(ALIASES, col)) {
      const [field, k] = ALIASES[col];
      value = k === undefined ? msg[field] : msg[field][k];
    } else if (Object.hasOwn(msg, col)) {
      value = msg[col];
    } else {
      const m = /^(.+)_(\d+)$/.exec(col);
      check(m && Array.isArray(msg[m[1]]), `${where}: CSV column ${col} is no field of the message`);
      check(Number(m[2]) >= 1, `${where}: CSV column ${col}: joint columns are 1-based`);
      value = msg[m[1]][Number(m[2]) - 1];
      arrayColumns.set(m[1], (arrayColumns.get(m[1]) ?? 0) + 1);
    }
    const text = row[col];
    if (typeof value === "number") {
      const x = Number(text);
      check(Object.is(value, x) || value === x || (Number.isNaN(value) && Number.isNaN(x)),
            `${where}.${col}: decoded ${value}, CSV ${text}`);
    } else {
      check(String(value) === text, `${where}.${col}: decoded ${JSON.stringify(value)}, CSV ${JSON.stringify(text)}`);
    }
  }
  for (const [field, n] of arrayColumns)
    check(msg[field].length === n, `${where}.${field}: ${msg[field].length} elements, the CSV has ${n} columns`);
}

export function stampNs(header) {
  return BigInt(header.stamp.sec) * 1000000000n + BigInt(header.stamp.nanosec);
}

// sensor_msgs/JointState against the pedalwave/JointState of the same header stamp: names,
// position = alpha, effort = SEA torque. Returns how many were paired.
export function checkJointStates(standard, own, where) {
  const byStamp = new Map(own.map((m) => [stampNs(m.header), m]));
  let paired = 0;
  for (const js of standard) {
    check(js.header.frame_id === "demo", `${where}: joint_states frame_id ${js.header.frame_id}`);
    const p = byStamp.get(stampNs(js.header));
    if (!p) continue;
    ++paired;
    check(js.name.length === p.alpha.length, `${where}: ${js.name.length} names for ${p.alpha.length} joints`);
    js.name.forEach((n, j) => check(n === `demo/joint_${j + 1}`, `${where}: joint name ${n}`));
    js.position.forEach((x, j) => check(x === p.alpha[j], `${where}: position[${j}] ${x} != alpha ${p.alpha[j]}`));
    js.effort.forEach((x, j) => check(x === p.tau_sea[j], `${where}: effort[${j}] ${x} != tau_sea ${p.tau_sea[j]}`));
    check(js.velocity.length === p.alpha.length && js.velocity.every(Number.isFinite), `${where}: velocity`);
  }
  return paired;
}
