// Writes an MCAP file with the official TypeScript writer (@mcap/core's McapWriter) for our reader
// to read (tests/runtime/telemetry/mcap/interop/run.sh), and the canonical listing of what it wrote:
//
//   node write_mcap.mjs OUT.mcap EXPECT.txt zstd|none|unchunked
//
// Three channels (two ros2msg schemas, one channel without a schema, metadata with spaces and
// newlines), 600 messages of 0 … 400 bytes with some log times going back, chunks of 4 KiB
// compressed with zstd (@foxglove/wasm-zstd; the lz4 package Foxglove ships only decompresses, so
// lz4 chunks are read in the other direction only) or stored uncompressed, or no chunks at all; an
// attachment and a metadata record the reader must skip. The listing is what
// pedalwave_mcap_dump prints: the header, schemas and channels by id, then the messages in
// log-time order (stable), data as hex.
import { McapWriter, TempBuffer } from "@mcap/core";
import * as zstd from "@foxglove/wasm-zstd";
import { writeFileSync } from "node:fs";

const [out, expectFile, mode] = process.argv.slice(2);
await zstd.isLoaded;

const hex = (u8) => Buffer.from(u8).toString("hex");
const utf8 = (s) => new TextEncoder().encode(s);
const buffer = new TempBuffer();
const writer = new McapWriter({
  writable: buffer,
  useChunks: mode !== "unchunked",
  chunkSize: 4096,
  compressChunk:
    mode === "zstd" ? (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) }) : undefined,
});
const header = { profile: "ros2", library: "@mcap/core peer" };
await writer.start(header);
const lines = [`header ${hex(utf8(header.profile))} ${hex(utf8(header.library))}`];

const schemas = [
  { name: "std_msgs/msg/String", encoding: "ros2msg", data: utf8("string data\n") },
  { name: "bin/msg/Blob", encoding: "ros2msg", data: Uint8Array.from({ length: 256 }, (_, i) => i) },
];
const schemaIds = [];
for (const s of schemas) {
  const id = await writer.registerSchema(s);
  schemaIds.push(id);
  lines.push(`schema ${id} ${hex(utf8(s.name))} ${hex(utf8(s.encoding))} ${hex(s.data)}`);
}
const channels = [
  { topic: "/a", schemaId: schemaIds[0], messageEncoding: "cdr",
    metadata: new Map([["offered_qos_profiles", "- history: 3\n  depth: 0\n"]]) },
  { topic: "/b b", schemaId: schemaIds[1], messageEncoding: "cdr", metadata: new Map() },
  { topic: "/raw", schemaId: 0, messageEncoding: "application/octet-stream", metadata: new Map([["k", "v w"], ["a", ""]]) },
];
const channelIds = [];
for (const c of channels) {
  const id = await writer.registerChannel(c);
  channelIds.push(id);
  const meta = [...c.metadata.entries()].sort(([a], [b]) => (a < b ? -1 : a > b ? 1 : 0))
    .map(([k, v]) => `${hex(utf8(k))}=${hex(utf8(v))}`).join(",");
  lines.push(`channel ${id} ${c.schemaId} ${hex(utf8(c.topic))} ${hex(utf8(c.messageEncoding))} ${meta || "-"}`);
}

// A small deterministic generator (xorshift32).
let state = 20261206;
const rand = () => {
  state ^= state << 13; state >>>= 0;
  state ^= state >>> 17;
  state ^= state << 5; state >>>= 0;
  return state;
};
const messages = [];
for (let i = 0; i < 600; i++) {
  const c = i % 3;
  const data = Uint8Array.from({ length: rand() % 401 }, () => rand() & 0xff);
  const logTime = 1_700_000_000_000_000_000n + BigInt(i) * 1_000_000n - (i % 13 === 4 ? 3_500_000n : 0n);
  const m = { channelId: channelIds[c], sequence: 7 + i, logTime, publishTime: logTime - 11n, data };
  await writer.addMessage(m);
  messages.push({ ...m, topic: channels[c].topic });
  if (i === 300) {
    await writer.addAttachment({ name: "note.txt", logTime, createTime: logTime, mediaType: "text/plain", data: utf8("skip me") });
    await writer.addMetadata({ name: "run", metadata: new Map([["robot", "demo"]]) });
  }
}
await writer.end();
messages.sort((a, b) => (a.logTime < b.logTime ? -1 : a.logTime > b.logTime ? 1 : 0));  // stable
for (const m of messages)
  lines.push(`message ${m.channelId} ${m.sequence} ${m.logTime} ${m.publishTime} ${hex(m.data) || "-"}`);
writeFileSync(out, buffer.get());
writeFileSync(expectFile, lines.join("\n") + "\n");
console.log(`${out}: ${messages.length} messages, ${buffer.get().length} bytes (${mode})`);
