// The MCAP file pedalwave_monitor --record run.mcap wrote, read with @mcap/core's indexed reader and
// decoded with @foxglove/rosmsg2-serialization from the file's own ros2msg schemas, against the CSV
// recording of the same run:
//   node check_mcap.mjs run.mcap CSV_STEM
import { McapIndexedReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import * as zstd from "@foxglove/wasm-zstd";
import lz4 from "@foxglove/wasm-lz4";
import { readFileSync } from "node:fs";
import { check, normalize, CSV_TOPICS, loadCsv, compareToRow, checkJointStates } from "./common.mjs";

const [file, stem] = process.argv.slice(2);
const bytes = new Uint8Array(readFileSync(file));
await zstd.isLoaded;
await lz4.isLoaded;
const reader = await McapIndexedReader.Initialize({
  readable: {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  },
  decompressHandlers: {
    zstd: (buffer, size) => zstd.decompress(buffer, Number(size)),
    lz4: (buffer, size) => lz4(buffer, Number(size)),
  },
});
check(reader.header.profile === "ros2", `profile ${reader.header.profile}`);

// Every topic the monitor subscribes to, with its type and the robot's writer QoS.
const expected = {
  "/demo/pedalwave/joint_state": ["pedalwave/msg/JointState", "best_effort", "volatile"],
  "/demo/pedalwave/controller_state": ["pedalwave/msg/ControllerState", "best_effort", "volatile"],
  "/demo/pedalwave/observer_state": ["pedalwave/msg/ObserverState", "best_effort", "volatile"],
  "/demo/pedalwave/loop_timing": ["pedalwave/msg/LoopTiming", "best_effort", "volatile"],
  "/demo/pedalwave/mode_event": ["pedalwave/msg/ModeEvent", "reliable", "transient_local"],
  "/demo/pedalwave/fault_event": ["pedalwave/msg/FaultEvent", "reliable", "transient_local"],
  "/demo/pedalwave/robot_description": ["pedalwave/msg/RobotDescription", "reliable", "transient_local"],
  "/pedalwave/command": ["pedalwave/msg/OperatorCommand", "reliable", "volatile"],
  "/pedalwave/emergency_stop": ["pedalwave/msg/OperatorCommand", "reliable", "volatile"],
  "/pedalwave/command_ack": ["pedalwave/msg/CommandAck", "reliable", "volatile"],
  "/demo/robot_description": ["std_msgs/msg/String", "reliable", "transient_local"],
  "/demo/joint_states": ["sensor_msgs/msg/JointState", "reliable", "volatile"],
  "/diagnostics": ["diagnostic_msgs/msg/DiagnosticArray", "reliable", "volatile"],
  "/tf": ["tf2_msgs/msg/TFMessage", "reliable", "volatile"],
};
const decoders = new Map();
const byTopic = new Map();
check(reader.channelsById.size === Object.keys(expected).length,
      `${reader.channelsById.size} channels, expected ${Object.keys(expected).length}`);
for (const ch of reader.channelsById.values()) {
  const e = expected[ch.topic];
  check(e, `unexpected channel ${ch.topic}`);
  const schema = reader.schemasById.get(ch.schemaId);
  check(schema && schema.name === e[0] && schema.encoding === "ros2msg", `${ch.topic}: schema ${schema?.name} ${schema?.encoding}`);
  check(ch.messageEncoding === "cdr", `${ch.topic}: message encoding ${ch.messageEncoding}`);
  const qos = ch.metadata.get("offered_qos_profiles") ?? "";
  check(qos.includes(`reliability: ${e[1]}`) && qos.includes(`durability: ${e[2]}`),
        `${ch.topic}: offered_qos_profiles ${JSON.stringify(qos)}`);
  decoders.set(ch.id, new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true })));
  byTopic.set(ch.topic, []);
}

// Every message of every channel, decoded.
let total = 0;
const publishTimes = new Map();
for await (const m of reader.readMessages()) {
  const ch = reader.channelsById.get(m.channelId);
  let msg;
  try {
    msg = normalize(decoders.get(m.channelId).readMessage(m.data));
  } catch (e) {
    check(false, `${ch.topic}: message ${m.sequence} does not decode: ${e}`);
  }
  byTopic.get(ch.topic).push(msg);
  publishTimes.set(msg, m.publishTime);
  ++total;
}
const stats = reader.statistics;
check(BigInt(total) === stats.messageCount, `read ${total} messages, statistics say ${stats.messageCount}`);

// pedalwave topics against the CSV recording of the same run (another monitor, same robot).
const report = [];
for (const [name, t] of Object.entries(CSV_TOPICS)) {
  const csv = loadCsv(stem, name);
  const msgs = byTopic.get(t.topic);
  if (name === "fault_event" && msgs.length === 0 && csv.rows.size === 0) {  // a run without faults
    report.push(`${name} 0/0`);
    continue;
  }
  check(msgs.length > 0, `${t.topic}: no message recorded`);
  // Reliable topics: within the cycles both recordings cover (the two recorders start and stop a
  // few ms apart), each message is in both, none missing.
  const keys = (xs) => xs.map(Number);
  const within = (k) => (!t.all || !t.key || (Number(k) >= lo && Number(k) <= hi));
  let lo = -Infinity, hi = Infinity;
  if (t.all && t.key) {
    const a = keys(msgs.map((m) => m[t.key])), b = keys([...csv.rows.keys()]);
    lo = Math.max(Math.min(...a), Math.min(...b));
    hi = Math.min(Math.max(...a), Math.max(...b));
    check(lo <= hi, `${t.topic}: the MCAP (${Math.min(...a)} … ${Math.max(...a)}) and the CSV (${Math.min(...b)} … ${Math.max(...b)}) share no ${t.key}`);
  }
  let paired = 0;
  for (const msg of msgs) {
    const key = t.key ? msg[t.key] : "";
    const row = csv.rows.get(key);
    if (!row) {
      check(!t.all || !within(key), `${t.topic}: ${t.key ?? "the description"} ${key} is not in ${csv.path}`);
      continue;
    }
    compareToRow(msg, row, csv.header, `${t.topic} (${t.key ?? ""} ${key})`);
    check(String(publishTimes.get(msg)) === row.source_time_ns,
          `${t.topic} ${key}: publish_time ${publishTimes.get(msg)} != the DDS source timestamp ${row.source_time_ns}`);
    ++paired;
  }
  const need = t.all ? [...csv.rows.keys()].filter(within).length : Math.ceil(0.8 * Math.min(csv.rows.size, msgs.length));
  check(paired >= need && need > 0, `${t.topic}: ${paired} messages paired with ${csv.path} rows, expected >= ${need}`);
  if (t.key && t.key === "event_seq") {
    msgs.forEach((m, i) => check(m.event_seq === String(i + 1), `${t.topic}: event_seq ${m.event_seq} at ${i + 1}`));
  }
  report.push(`${name} ${paired}/${msgs.length}`);
}

// The standard topics: joint_states against pedalwave's joint_state of the same stamp, the URDF,
// /tf (odom → link_1 → … → link_N of robot demo), /diagnostics.
const own = byTopic.get("/demo/pedalwave/joint_state");
const js = byTopic.get("/demo/joint_states");
const pairedJs = checkJointStates(js, own, "/demo/joint_states");
check(pairedJs >= 0.8 * Math.min(js.length, own.length), `joint_states: ${pairedJs} of ${js.length} paired`);
const links = byTopic.get("/demo/pedalwave/robot_description")[0].links;
const urdf = byTopic.get("/demo/robot_description");
check(urdf.length === 1 && urdf[0].data.includes("<robot") && urdf[0].data.includes(`demo/link_${links}`),
      `robot_description: ${urdf.length} messages`);
const tf = byTopic.get("/tf");
check(tf.length > 0, "/tf: no message");
for (const m of tf) {
  check(m.transforms.length === links, `/tf: ${m.transforms.length} transforms for ${links} links`);
  m.transforms.forEach((t, k) => {
    check(t.child_frame_id === `demo/link_${k + 1}` &&
          t.header.frame_id === (k === 0 ? "demo/odom" : `demo/link_${k}`), `/tf: transform ${k}: ${t.header.frame_id} → ${t.child_frame_id}`);
    const q = t.transform.rotation;
    check(Math.abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1) < 1e-9, `/tf: transform ${k}: not a unit quaternion`);
  });
}
const diag = byTopic.get("/diagnostics");
check(diag.length > 0 && diag.some((d) => d.status.some((s) => s.name === "demo: mode")), "/diagnostics: no 'demo: mode' status");
console.log(`mcap: ${file}: ${total} messages on ${reader.channelsById.size} channels decoded; ` +
            `${report.join(", ")} equal to the CSV; joint_states ${pairedJs}/${js.length} = joint_state; ` +
            `tf ${tf.length}, diagnostics ${diag.length}, urdf ${urdf.length}; ${reader.chunkIndexes.length} chunks`);
