// Decode every message of a rosbag2 folder with Foxglove's own JavaScript readers and print JSON.
//
//   node tests/js/read_bag.mjs BAG_DIR > decoded.json
//
// MCAP: @mcap/core's indexed reader (summary, chunk and message indexes, CRCs checked), each
// channel's schema parsed by @foxglove/rosmsg and decoded by @foxglove/rosmsg2-serialization,
// which is what Foxglove does with a ROS 2 MCAP file.
// sqlite3: @foxglove/rosbag2-web (sql.js; in node the wasm bytes are handed to it). Types it ships
// definitions for are decoded by rosbag2-web itself; the others with the definitions the bag embeds
// in its `message_definitions` table.
//
// Output: {"reader": ..., "topics": {name: {"type": ..., "messages": [{"t_ns": "...", "msg": ...}]}}}
// with typed arrays as lists, bigints and non-finite floats as strings.

import { readFile, readdir, open } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";

import { McapIndexedReader } from "@mcap/core";
import { parse as parseMessageDefinition } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { Rosbag2, ROS2_TO_DEFINITIONS } from "@foxglove/rosbag2";
import { SqliteSqljs } from "@foxglove/rosbag2-web";

const require = createRequire(import.meta.url);

function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (typeof value === "number") return Number.isFinite(value) ? value : String(value);
  if (ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (value && typeof value === "object") {
    const out = {};
    for (const [k, v] of Object.entries(value)) out[k] = plain(v);
    return out;
  }
  return value;
}

function addMessage(topics, topic, type, tNs, msg) {
  if (!topics[topic]) topics[topic] = { type, messages: [] };
  topics[topic].messages.push({ t_ns: tNs.toString(), msg: plain(msg) });
}

async function readMcap(file) {
  const handle = await open(file, "r");
  const readable = {
    size: async () => BigInt((await handle.stat()).size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  if (reader.header.profile !== "ros2") throw new Error(`profile ${reader.header.profile}, expected ros2`);
  const decoders = new Map();
  const topics = {};
  for (const channel of reader.channelsById.values()) {
    const schema = reader.schemasById.get(channel.schemaId);
    if (schema.encoding !== "ros2msg") throw new Error(`schema encoding ${schema.encoding}`);
    if (channel.messageEncoding !== "cdr") throw new Error(`message encoding ${channel.messageEncoding}`);
    const definitions = parseMessageDefinition(new TextDecoder().decode(schema.data), { ros2: true });
    decoders.set(channel.id, new MessageReader(definitions));
    topics[channel.topic] = { type: schema.name, messages: [] };
  }
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(message.channelId);
    const schema = reader.schemasById.get(channel.schemaId);
    addMessage(topics, channel.topic, schema.name, message.logTime, decoders.get(message.channelId).readMessage(message.data));
  }
  await handle.close();
  return { reader: "@mcap/core + @foxglove/rosmsg2-serialization", topics };
}

async function readDb3(file) {
  const wasmBinary = await readFile(require.resolve("@foxglove/sql.js/dist/sql-wasm.wasm"));
  const SQL = await SqliteSqljs.Initialize({ wasmBinary });
  const bytes = new Uint8Array(await readFile(file));

  // The definitions the bag embeds, for the types rosbag2-web does not ship.
  const db = new SQL.Database(bytes);
  const embedded = new Map();
  for (const [type, encoding, text] of db.exec(
    "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions",
  )[0]?.values ?? []) {
    if (encoding !== "ros2msg") throw new Error(`definition encoding ${encoding}`);
    embedded.set(type, new MessageReader(parseMessageDefinition(text, { ros2: true })));
  }
  db.close();

  const bag = new Rosbag2([new SqliteSqljs(bytes)]);
  await bag.open();
  const topics = {};
  const known = [];
  const custom = [];
  for (const topic of await bag.readTopics()) {
    topics[topic.name] = { type: topic.type, messages: [] };
    (ROS2_TO_DEFINITIONS.has(topic.type) ? known : custom).push(topic.name);
  }
  if (known.length > 0) {
    for await (const m of bag.readMessages({ topics: known })) {
      addMessage(topics, m.topic.name, m.topic.type, BigInt(m.timestamp.sec) * 1000000000n + BigInt(m.timestamp.nsec), m.value);
    }
  }
  if (custom.length > 0) {
    for await (const m of bag.readMessages({ topics: custom, rawMessages: true })) {
      const decoder = embedded.get(m.topic.type);
      if (!decoder) throw new Error(`no definition for ${m.topic.type}`);
      addMessage(topics, m.topic.name, m.topic.type, BigInt(m.timestamp.sec) * 1000000000n + BigInt(m.timestamp.nsec), decoder.readMessage(m.data));
    }
  }
  await bag.close();
  return { reader: "@foxglove/rosbag2-web", topics, builtin_topics: known, embedded_topics: custom };
}

async function main() {
  const dir = process.argv[2];
  if (!dir) {
    console.error("usage: node read_bag.mjs BAG_DIR");
    process.exit(2);
  }
  const files = (await readdir(dir)).sort();
  const mcap = files.find((f) => f.endsWith(".mcap"));
  const db3 = files.find((f) => f.endsWith(".db3"));
  const result = mcap ? await readMcap(path.join(dir, mcap)) : await readDb3(path.join(dir, db3));
  process.stdout.write(JSON.stringify(result));
}

main().catch((err) => {
  console.error(err?.stack ?? String(err));
  process.exit(1);
});
