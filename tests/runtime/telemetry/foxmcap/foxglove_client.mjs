// The Foxglove live view of pedalwave_monitor --foxglove PORT, through the official client
// (@foxglove/ws-protocol's FoxgloveClient over the `ws` package), decoding with
// @foxglove/rosmsg2-serialization from the advertised ros2msg schemas.
//   node foxglove_client.mjs ws://127.0.0.1:PORT OUT.json   collect (during the run)
//   node foxglove_client.mjs --check OUT.json CSV_STEM      compare with the CSV (after the run)
import { readFileSync, writeFileSync } from "node:fs";
import { check, normalize, CSV_TOPICS, loadCsv, compareToRow, checkJointStates } from "./common.mjs";

if (process.argv[2] === "--check") {
  const [, , , out, stem] = process.argv;
  const got = JSON.parse(readFileSync(out, "utf8"));
  const own = got.messages["/demo/pedalwave/joint_state"];
  const csv = loadCsv(stem, "joint_state");
  let paired = 0;
  for (const m of own) {
    const row = csv.rows.get(m.seq);
    if (!row) continue;
    compareToRow(m, row, csv.header, `foxglove /demo/pedalwave/joint_state (seq ${m.seq})`);
    ++paired;
  }
  check(paired >= 0.8 * Math.min(own.length, csv.rows.size) && paired > 50,
        `foxglove joint_state: ${paired} of ${own.length} paired with ${csv.rows.size} CSV rows`);
  const js = got.messages["/demo/joint_states"];
  const pairedJs = checkJointStates(js, own, "foxglove /demo/joint_states");
  check(pairedJs >= 0.8 * Math.min(js.length, own.length) && pairedJs > 50, `foxglove joint_states: ${pairedJs} of ${js.length} paired`);
  console.log(`foxglove: joint_state ${paired}/${own.length} equal to the CSV rows, joint_states ` +
              `${pairedJs}/${js.length} = joint_state, diagnostics ${got.messages["/diagnostics"].length}; ` +
              `${got.afterUnsubscribe} joint_states after unsubscribing`);
  process.exit(0);
}

const wsProtocol = await import("@foxglove/ws-protocol");
const FoxgloveClient = wsProtocol.FoxgloveClient ?? wsProtocol.default.FoxgloveClient;  // CommonJS from ESM
const { WebSocket } = await import("ws");
const { parse } = await import("@foxglove/rosmsg");
const { MessageReader } = await import("@foxglove/rosmsg2-serialization");
const [url, out] = process.argv.slice(2);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
setTimeout(() => check(false, "foxglove client: no end within 20 s"), 20000).unref();

const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
let serverInfo = null;
const channels = new Map();
const statuses = [];
const subs = new Map();   // subscription id → {topic, reader}
const messages = {};
let unsubscribedAt = null;
let afterUnsubscribe = 0;
client.on("error", (e) => check(false, `foxglove client: ${e?.message ?? e}`));
client.on("serverInfo", (i) => { serverInfo = i; });
client.on("status", (s) => statuses.push(s));
client.on("advertise", (chs) => { for (const c of chs) channels.set(c.topic, c); });
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const s = subs.get(subscriptionId);
  check(s, `message for unknown subscription ${subscriptionId}`);
  check(typeof timestamp === "bigint" && timestamp > 1600000000000000000n, `timestamp ${timestamp}`);
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  let msg;
  try {
    msg = normalize(s.reader.readMessage(bytes));
  } catch (e) {
    check(false, `${s.topic}: does not decode: ${e}`);
  }
  if (s.topic === "/demo/joint_states" && unsubscribedAt !== null && Date.now() - unsubscribedAt > 300) ++afterUnsubscribe;
  (messages[s.topic] ??= []).push(msg);
});

for (let i = 0; i < 100 && (serverInfo === null || channels.size === 0); ++i) await sleep(20);
check(serverInfo !== null, "no serverInfo");
check(channels.size === 14, `${channels.size} channels advertised, expected 14`);
for (const c of channels.values()) {
  check(c.encoding === "cdr" && c.schemaEncoding === "ros2msg" && c.schema.length > 0,
        `${c.topic}: encoding ${c.encoding}, schema ${c.schemaName} ${c.schemaEncoding}`);
  parse(c.schema, { ros2: true });  // every advertised schema parses
}
const subscribe = (topic) => {
  const c = channels.get(topic);
  check(c, `${topic} not advertised`);
  const id = client.subscribe(c.id);
  subs.set(id, { topic, reader: new MessageReader(parse(c.schema, { ros2: true })) });
  messages[topic] = [];
  return id;
};
const jsSub = subscribe("/demo/joint_states");
subscribe("/demo/pedalwave/joint_state");
subscribe("/diagnostics");
client.subscribe(9999);  // no such channel: an error status
await sleep(1500);
client.unsubscribe(jsSub);
unsubscribedAt = Date.now();
await sleep(1000);
client.close();

check(statuses.some((s) => s.level === 2 && s.message.includes("no channel 9999")), `statuses ${JSON.stringify(statuses)}`);
check(afterUnsubscribe === 0, `${afterUnsubscribe} joint_states messages after unsubscribing`);
for (const t of ["/demo/joint_states", "/demo/pedalwave/joint_state", "/diagnostics"])
  check(messages[t].length > 0, `${t}: no message`);
writeFileSync(out, JSON.stringify({ messages, afterUnsubscribe }));
console.log(`foxglove: ${serverInfo.name}: ${channels.size} channels; received ` +
            Object.entries(messages).map(([t, m]) => `${t} ${m.length}`).join(", "));
process.exit(0);
