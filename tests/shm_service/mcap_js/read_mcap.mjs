// An independent reader of our recordings: the npm @mcap packages (TypeScript reference
// implementation). Prints a JSON summary of FILE read twice, through the summary and indexes
// (McapIndexedReader) and record by record from the start (McapStreamReader), with CRCs checked,
// and every JSON payload checked against its channel's jsonschema (required keys, number types,
// array lengths).  Usage: node read_mcap.mjs FILE
import { open, readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers } from "@mcap/support";

const path = process.argv[2];
const decompressHandlers = await loadDecompressHandlers();
const decoder = new TextDecoder();

function check(schema, payload, where) {
  if (schema.type !== "object" || typeof payload !== "object" || payload === null || Array.isArray(payload)) {
    throw new Error(`${where}: payload is not an object`);
  }
  for (const key of schema.required ?? []) {
    if (!(key in payload)) throw new Error(`${where}: missing required key ${key}`);
  }
  for (const [key, spec] of Object.entries(schema.properties ?? {})) {
    const value = payload[key];
    if (value === undefined) continue;
    if (spec.type === "number") {
      if (typeof value !== "number" || !Number.isFinite(value)) throw new Error(`${where}: ${key} is not a finite number`);
    } else if (spec.type === "array") {
      if (!Array.isArray(value) || !value.every((v) => typeof v === "number" && Number.isFinite(v))) {
        throw new Error(`${where}: ${key} is not an array of finite numbers`);
      }
      if (spec.minItems !== undefined && value.length < spec.minItems) throw new Error(`${where}: ${key} has too few items`);
      if (spec.maxItems !== undefined && value.length > spec.maxItems) throw new Error(`${where}: ${key} has too many items`);
    }
  }
}

function flatten(payload, schema) {
  const out = [];
  for (const key of Object.keys(schema.properties)) {
    const value = payload[key];
    if (Array.isArray(value)) out.push(...value);
    else out.push(value);
  }
  return out;
}

const handle = await open(path, "r");
const reader = await McapIndexedReader.Initialize({ readable: new FileHandleReadable(handle), decompressHandlers });
const schemas = new Map();
for (const [id, schema] of reader.schemasById) {
  schemas.set(id, { name: schema.name, encoding: schema.encoding, json: JSON.parse(decoder.decode(schema.data)) });
}
const topics = {};
for await (const message of reader.readMessages({ validateCrcs: true })) {
  const channel = reader.channelsById.get(message.channelId);
  const schema = schemas.get(channel.schemaId);
  const payload = JSON.parse(decoder.decode(message.data));
  check(schema.json, payload, `${channel.topic} at ${message.logTime}`);
  const values = flatten(payload, schema.json);
  let t = topics[channel.topic];
  if (t === undefined) {
    t = topics[channel.topic] = {
      schema: schema.name, schema_encoding: schema.encoding, message_encoding: channel.messageEncoding,
      count: 0, first_log_time: message.logTime.toString(), last_log_time: "0", log_time_sum: 0n,
      first: values, last: values, sums: values.map(() => 0), in_order: true,
    };
  }
  if (t.count > 0 && BigInt(t.last_log_time) >= message.logTime) t.in_order = false;
  t.count += 1;
  t.last_log_time = message.logTime.toString();
  t.log_time_sum += message.logTime;
  t.last = values;
  values.forEach((v, i) => { t.sums[i] += v; });
}
for (const t of Object.values(topics)) t.log_time_sum = t.log_time_sum.toString();
const attachments = [];
for await (const a of reader.readAttachments({ validateCrcs: true })) {
  attachments.push({ name: a.name, media_type: a.mediaType, data: decoder.decode(a.data) });
}
const metadata = {};
for await (const m of reader.readMetadata()) metadata[m.name] = Object.fromEntries(m.metadata);
const statistics = reader.statistics && {
  message_count: reader.statistics.messageCount.toString(), channel_count: reader.statistics.channelCount,
  chunk_count: reader.statistics.chunkCount, attachment_count: reader.statistics.attachmentCount,
  metadata_count: reader.statistics.metadataCount,
};
await handle.close();

// the same file record by record, as a reader that follows a stream does
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(await readFile(path));
const streamed = {};
const streamChannels = new Map();
let record;
let sawFooter = false;
while ((record = stream.nextRecord()) !== undefined) {
  if (record.type === "Channel") streamChannels.set(record.id, record.topic);
  if (record.type === "Message") {
    const topic = streamChannels.get(record.channelId);
    streamed[topic] = (streamed[topic] ?? 0) + 1;
  }
  if (record.type === "Footer") sawFooter = true;
}
console.log(JSON.stringify({
  header: { profile: reader.header.profile, library: reader.header.library },
  statistics, topics, attachments, metadata, stream: { topics: streamed, done: stream.done(), footer: sawFooter },
}));
