// Foxglove's own client library (@foxglove/ws-protocol, over the `ws` WebSocket package) against a live imubridge,
// for tests/cli_foxglove_test.cpp: subscribes to every channel the server advertises and prints, one JSON object per
// line on stdout, the server's info, its channels, every status and every message with its channel's topic, the
// receive timestamp (ns, as a decimal string: it may exceed 2^53) and the payload as text. Ends when the server
// closes the connection. Usage: node foxglove_client.cjs ws://127.0.0.1:PORT
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const out = (object) => process.stdout.write(JSON.stringify(object) + "\n");
const client = new FoxgloveClient({
  ws: new WebSocket(process.argv[2], [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const channels = new Map(); // subscription id -> channel
const decoder = new TextDecoder();

client.on("serverInfo", (info) => out({ op: "serverInfo", info }));
client.on("status", (status) => out({ op: "status", status }));
client.on("advertise", (advertised) => {
  out({ op: "advertise", channels: advertised });
  for (const channel of advertised) channels.set(client.subscribe(channel.id), channel);
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = channels.get(subscriptionId);
  out({ op: "message", topic: channel.topic, receiveTime: timestamp.toString(), data: decoder.decode(data) });
});
client.on("error", (error) => process.stderr.write(`error: ${error}\n`));
client.on("close", () => process.exit(0));
