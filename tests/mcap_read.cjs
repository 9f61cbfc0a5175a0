// Reads an MCAP file with the MCAP project's own TypeScript reader (@mcap/core) and prints what it found as JSON:
// the indexed reader (summary, chunk and message indexes, CRCs checked) gives every message, its text, per topic; the
// stream reader (every record from the start, chunk CRCs checked) counts them again. Used by cli_mcap_test.
// Usage: NODE_PATH=<dir>/node_modules node mcap_read.cjs FILE.mcap
"use strict";
const fs = require("fs");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");

async function main() {
  const file = process.argv[2];
  const handle = await fs.promises.open(file, "r");
  const size = (await handle.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  const decoder = new TextDecoder();
  const topics = {};
  for (const [id, channel] of reader.channelsById) {
    const schema = reader.schemasById.get(channel.schemaId);
    topics[channel.topic] = {
      channel_id: id,
      schema: schema ? schema.name : "",
      schema_encoding: schema ? schema.encoding : "",
      schema_valid_json: schema ? isJson(decoder.decode(schema.data)) : false,
      message_encoding: channel.messageEncoding,
      metadata: Object.fromEntries(channel.metadata),
      invalid_json: 0,
      messages: [],
    };
  }
  const byId = new Map([...reader.channelsById].map(([id, c]) => [id, topics[c.topic]]));
  let previous = -1n;
  let in_time_order = true;
  let count = 0;
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    if (message.logTime < previous) in_time_order = false;
    previous = message.logTime;
    // The text as read: JavaScript's numbers would round 64-bit integers (wall_ns) that the test compares exactly.
    const text = decoder.decode(message.data);
    const topic = byId.get(message.channelId);
    if (!isJson(text)) ++topic.invalid_json;
    topic.messages.push({
      sequence: message.sequence,
      log_time: message.logTime.toString(),
      publish_time: message.publishTime.toString(),
      text,
    });
    ++count;
  }
  for (const topic of Object.values(topics)) topic.messages.sort((a, b) => a.sequence - b.sequence);

  const stream = new McapStreamReader({ validateCrcs: true });
  stream.append(new Uint8Array(fs.readFileSync(file)));
  const streamed = {};
  let record;
  let footer = false;
  while ((record = stream.nextRecord())) {
    if (record.type === "Message") {
      const topic = reader.channelsById.get(record.channelId).topic;
      streamed[topic] = (streamed[topic] || 0) + 1;
    }
    if (record.type === "Footer") footer = true;
  }
  const s = reader.statistics;
  const out = {
    library: reader.header.library,
    profile: reader.header.profile,
    chunk_indexes: reader.chunkIndexes.length,
    statistics: s && {
      message_count: s.messageCount.toString(),
      channel_count: s.channelCount,
      chunk_count: s.chunkCount,
      message_start_time: s.messageStartTime.toString(),
      message_end_time: s.messageEndTime.toString(),
      channel_message_counts: Object.fromEntries(
        [...s.channelMessageCounts].map(([id, n]) => [reader.channelsById.get(id).topic, n.toString()])),
    },
    indexed_messages: count,
    in_time_order,
    stream: { messages: streamed, footer, done: stream.done() },
    topics,
  };
  process.stdout.write(JSON.stringify(out));
  await handle.close();
}

function isJson(text) {
  try {
    JSON.parse(text);
    return true;
  } catch {
    return false;
  }
}

main().catch((error) => {
  process.stderr.write(`mcap_read: ${error && error.message ? error.message : error}\n`);
  process.exit(1);
});
