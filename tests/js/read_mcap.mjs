// Reads an MCAP file with Foxglove's own reader (@mcap/core's McapIndexedReader, the one the
// Foxglove app is built on) and prints what it found as JSON: messages per topic, the summary's
// message count, and the first error, if any. Used by tests/test_mcap_readers.py.
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";

const handle = await open(process.argv[2], "r");
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, length) => {
    const buffer = new Uint8Array(Number(length));
    await handle.read(buffer, 0, Number(length), Number(offset));
    return buffer;
  },
};
const out = { topics: {}, messages: 0, summary_messages: null, error: null };
try {
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
  });
  out.summary_messages = Number(reader.statistics?.messageCount ?? -1);
  for await (const message of reader.readMessages()) {
    const topic = reader.channelsById.get(message.channelId).topic;
    out.topics[topic] = (out.topics[topic] ?? 0) + 1;
    out.messages += 1;
  }
} catch (error) {
  out.error = String(error?.message ?? error);
}
await handle.close();
console.log(JSON.stringify(out));
