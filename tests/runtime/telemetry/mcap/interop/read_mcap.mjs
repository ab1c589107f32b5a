// Reads an MCAP file written by pedalwave::mcap with the official TypeScript readers and checks it
// against what the writer says it published:
//
//   node read_mcap.mjs FILE.mcap EXPECT.jsonl MIN_CHUNKS
//
// - McapIndexedReader (footer, summary CRC, summary offsets, chunk indexes, message indexes):
//   header, statistics, schemas (ros2msg), channels (cdr, offered_qos_profiles), the data-section
//   CRC, every message decoded with @foxglove/rosmsg2-serialization from the file's own ros2msg
//   schema (parsed by @foxglove/rosmsg) and compared field by field with EXPECT, with no trailing
//   bytes; topic and time-window queries and reverse order answered from the indexes.
// - McapStreamReader (a linear read, fed in small pieces, chunk CRCs validated): the same messages
//   in file order, and the file's end reached.
// - What a crash leaves: the file cut after a chunk's message indexes, and cut inside the next
//   chunk: the stream reader gives exactly the messages of the complete chunks, without an error.
//
// Exits non-zero with the first difference found.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { crc32 } from "@foxglove/crc";
import * as zstd from "@foxglove/wasm-zstd";
import lz4 from "@foxglove/wasm-lz4";
import { readFileSync } from "node:fs";

const [file, expectFile, minChunksArg] = process.argv.slice(2);
const minChunks = Number(minChunksArg ?? 1);
const bytes = new Uint8Array(readFileSync(file));
const expected = readFileSync(expectFile, "utf8").trim().split("\n").map((l) => JSON.parse(l));

function fail(what) {
  console.error(`mcap interop: ${file}: FAILED: ${what}`);
  process.exit(1);
}
function check(cond, what) {
  if (!cond) fail(what);
}

await zstd.isLoaded;
await lz4.isLoaded;
const decompressHandlers = {
  zstd: (buffer, size) => zstd.decompress(buffer, Number(size)),
  lz4: (buffer, size) => lz4(buffer, Number(size)),
};

// Decoded values in the expectation's terms: typed arrays as arrays, int64 (BigInt) as strings.
function normalize(v) {
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
function sameValue(a, b, path) {
  if (Array.isArray(b)) {
    check(Array.isArray(a) && a.length === b.length, `${path}: ${JSON.stringify(a)} != ${JSON.stringify(b)}`);
    b.forEach((x, i) => sameValue(a[i], x, `${path}[${i}]`));
  } else if (b !== null && typeof b === "object") {
    check(a !== null && typeof a === "object", `${path}: ${JSON.stringify(a)} is not an object`);
    const ka = Object.keys(a).sort(), kb = Object.keys(b).sort();
    check(JSON.stringify(ka) === JSON.stringify(kb), `${path}: fields ${ka} != ${kb}`);
    for (const k of kb) sameValue(a[k], b[k], `${path}.${k}`);
  } else {
    check(Object.is(a, b) || (a === 0 && b === 0), `${path}: decoded ${JSON.stringify(a)}, published ${JSON.stringify(b)}`);
  }
}

// One MessageReader per schema, from the file's own ros2msg text.
const readers = new Map();
function decoderFor(schema) {
  if (!readers.has(schema.id)) {
    check(schema.encoding === "ros2msg", `schema ${schema.name}: encoding ${schema.encoding}`);
    const text = new TextDecoder().decode(schema.data);
    readers.set(schema.id, new MessageReader(parse(text, { ros2: true })));
  }
  return readers.get(schema.id);
}
function checkMessage(m, channel, schema, want, where) {
  check(channel.topic === want.topic, `${where}: topic ${channel.topic}, expected ${want.topic}`);
  check(m.sequence === want.sequence, `${where}: sequence ${m.sequence}, expected ${want.sequence}`);
  check(m.logTime === BigInt(want.log_time), `${where}: log_time ${m.logTime}, expected ${want.log_time}`);
  check(m.publishTime === BigInt(want.publish_time), `${where}: publish_time ${m.publishTime}`);
  const reader = decoderFor(schema);
  const decoded = reader.readMessage(m.data);
  check(!reader.lastReadHadTrailingBytes(), `${where}: ${channel.topic} #${m.sequence} has trailing bytes`);
  sameValue(normalize(decoded), want.msg, `${where} ${channel.topic} #${m.sequence}`);
}
const key = (topic, seq) => `${topic}#${seq}`;
const byKey = new Map(expected.map((e) => [key(e.topic, e.sequence), e]));
check(byKey.size === expected.length, "the expectation has duplicate (topic, sequence)");

// ---- Indexed reader -------------------------------------------------------------------------
const readable = {
  size: async () => BigInt(bytes.length),
  read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
};
const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
check(indexed.header.profile === "ros2", `profile ${indexed.header.profile}`);
check(indexed.footer.summaryCrc !== 0, "no summary CRC"); // Initialize() validated it
const stats = indexed.statistics;
check(stats !== undefined, "no Statistics record");
check(stats.messageCount === BigInt(expected.length), `statistics: ${stats.messageCount} messages, wrote ${expected.length}`);
check(stats.chunkCount === indexed.chunkIndexes.length, "statistics chunk count != chunk indexes");
check(indexed.chunkIndexes.length >= minChunks, `${indexed.chunkIndexes.length} chunks, expected >= ${minChunks}`);
for (const wantOp of [3, 4, 8, 11]) check(indexed.summaryOffsetsByOpcode.has(wantOp), `no summary offset for op ${wantOp}`);
const perTopic = new Map();
for (const e of expected) perTopic.set(e.topic, (perTopic.get(e.topic) ?? 0) + 1);
for (const [id, ch] of indexed.channelsById) {
  check(ch.messageEncoding === "cdr", `${ch.topic}: message encoding ${ch.messageEncoding}`);
  check((ch.metadata.get("offered_qos_profiles") ?? "").includes("reliability:"), `${ch.topic}: no offered_qos_profiles`);
  check(stats.channelMessageCounts.get(id) === BigInt(perTopic.get(ch.topic) ?? 0), `${ch.topic}: statistics count`);
}
check(indexed.channelsById.size === perTopic.size, "channels in the summary != topics written");
// The data section CRC: every byte before the DataEnd record (leading magic and Header included).
check(indexed.dataSectionCrc === crc32(bytes.subarray(0, Number(indexed.dataEndOffset))),
      `data section CRC ${indexed.dataSectionCrc} != ${crc32(bytes.subarray(0, Number(indexed.dataEndOffset)))}`);

let count = 0;
let lastTime = -1n;
for await (const m of indexed.readMessages()) {
  const channel = indexed.channelsById.get(m.channelId);
  const want = byKey.get(key(channel.topic, m.sequence));
  check(want !== undefined, `indexed: unexpected ${channel.topic} #${m.sequence}`);
  check(m.logTime >= lastTime, "indexed: messages not in log-time order");
  lastTime = m.logTime;
  checkMessage(m, channel, indexed.schemasById.get(channel.schemaId), want, "indexed");
  ++count;
}
check(count === expected.length, `indexed: read ${count} messages, wrote ${expected.length}`);

// Queries the indexes answer: one topic in a time window, and everything in reverse.
const times = expected.map((e) => BigInt(e.log_time)).sort((a, b) => (a < b ? -1 : a > b ? 1 : 0));
const t0 = times[Math.floor(times.length / 4)], t1 = times[Math.floor((3 * times.length) / 4)];
const topic = "/pedalwave/joint_states";
const wantWindow = expected.filter((e) => e.topic === topic && BigInt(e.log_time) >= t0 && BigInt(e.log_time) <= t1).length;
let gotWindow = 0;
for await (const m of indexed.readMessages({ topics: [topic], startTime: t0, endTime: t1 })) {
  check(indexed.channelsById.get(m.channelId).topic === topic, "window: other topic");
  ++gotWindow;
}
check(wantWindow > 0 && gotWindow === wantWindow, `window query: ${gotWindow} messages, expected ${wantWindow}`);
let reverse = 0;
lastTime = 1n << 64n;
for await (const m of indexed.readMessages({ reverse: true })) {
  check(m.logTime <= lastTime, "reverse: not in reverse order");
  lastTime = m.logTime;
  ++reverse;
}
check(reverse === expected.length, `reverse: ${reverse} messages`);

// ---- Stream reader --------------------------------------------------------------------------
// Feeds `data` in pieces of `step` bytes; returns the messages (with channel and schema).
function streamRead(data, step) {
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  const schemas = new Map(), channels = new Map(), messages = [];
  let dataEnd = false, statistics = undefined;
  for (let at = 0; at < data.length; at += step) {
    reader.append(data.subarray(at, Math.min(data.length, at + step)));
    for (let r; (r = reader.nextRecord()); ) {
      if (r.type === "Schema") schemas.set(r.id, r);
      else if (r.type === "Channel") channels.set(r.id, r);
      else if (r.type === "Message") {
        const channel = channels.get(r.channelId);
        check(channel !== undefined, `stream: message before its channel ${r.channelId}`);
        messages.push({ m: r, channel, schema: schemas.get(channel.schemaId) });
      } else if (r.type === "DataEnd") dataEnd = true;
      else if (r.type === "Statistics") statistics = r;
    }
  }
  return { messages, done: reader.done(), dataEnd, statistics };
}
const whole = streamRead(bytes, 4093);
check(whole.done && whole.dataEnd && whole.statistics !== undefined, "stream: did not reach the end of a valid file");
check(whole.messages.length === expected.length, `stream: ${whole.messages.length} messages, wrote ${expected.length}`);
whole.messages.forEach(({ m, channel, schema }, i) => {
  const want = expected[i];  // file order is write order
  checkMessage(m, channel, schema, want, `stream[${i}]`);
});

// ---- What a crash leaves ----------------------------------------------------------------------
const chunks = [...indexed.chunkIndexes].sort((a, b) => (a.chunkStartOffset < b.chunkStartOffset ? -1 : 1));
check(chunks.length >= 2, "need two chunks for the crash check");
const k = chunks.length >= 3 ? 1 : 0;  // cut after chunk k's message indexes / inside chunk k+1
const afterK = Number(chunks[k].chunkStartOffset + chunks[k].chunkLength + chunks[k].messageIndexLength);
// Messages in chunks 0..k: the entries of their message indexes (each 16 bytes after the record's
// opcode, length and channel id and the array's byte length).
let inFirstChunks = 0;
for (let i = 0; i <= k; ++i) {
  for (const [, off] of chunks[i].messageIndexOffsets) {
    const view = new DataView(bytes.buffer, bytes.byteOffset + Number(off));
    inFirstChunks += view.getUint32(1 + 8 + 2, true) / 16;
  }
}
for (const [cut, label] of [[afterK, "after a chunk's indexes"], [afterK + Number(chunks[k + 1].chunkLength) / 2, "inside a chunk"]]) {
  const part = streamRead(bytes.subarray(0, Math.floor(cut)), 1000);
  check(!part.done, `crash (${label}): a cut file read as complete`);
  check(part.messages.length === inFirstChunks,
        `crash (${label}): ${part.messages.length} messages, the completed chunks hold ${inFirstChunks}`);
  part.messages.forEach(({ m, channel, schema }, i) => checkMessage(m, channel, schema, expected[i], `crash[${i}]`));
}

console.log(
  `mcap interop: ${file}: OK — ${expected.length} messages on ${perTopic.size} topics in ` +
    `${indexed.chunkIndexes.length} ${indexed.chunkIndexes[0]?.compression || "uncompressed"} chunks: ` +
    `indexed and stream readers decode every message to the published values; ` +
    `window query ${gotWindow}, reverse ${reverse}; a file cut after chunk ${k + 1} gives its ${inFirstChunks} messages`,
);
