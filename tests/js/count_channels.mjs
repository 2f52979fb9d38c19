// Foxglove's own client (@foxglove/ws-protocol) for tests/test_liveview_npm_client.py.
// usage: node count_channels.mjs ws://HOST:PORT TIMEOUT_S [SUBSCRIBE_AFTER_MS] [RECONNECTS] [KEEP_TOPICS]
// Connects (retrying until the server listens), subscribes to every channel as it is advertised (after
// SUBSCRIBE_AFTER_MS, default 0), counts messages per topic until the server closes the connection, then prints
// {"protocol", "channels": {topic: {schemaName, encoding}}, "counts": {topic: n}, "statuses": [...],
// "connections": [{topic: n} per connection]} as JSON. With RECONNECTS > 0 it connects again to the same URL
// (retrying until a server listens there) after each of the first RECONNECTS closes, as Foxglove's app does.
// KEEP_TOPICS (comma-separated): the payloads of these topics' messages are kept in "messages": {topic: [..]}, as
// text for JSON channels and base64 for the others, and their channels carry the advertised schemaEncoding and
// schema (so that the test decodes protobuf payloads with the schema the server sent).
import wsProtocol from "@foxglove/ws-protocol";
const { FoxgloveClient } = wsProtocol;
import WebSocket from "ws";

const [url, timeoutS, afterMs] = [process.argv[2], Number(process.argv[3] ?? 60), Number(process.argv[4] ?? 0)];
let reconnects = Number(process.argv[5] ?? 0);
const keep = new Set((process.argv[6] ?? "").split(",").filter((t) => t));
const deadline = Date.now() + timeoutS * 1000;
const out = { protocol: null, channels: {}, counts: {}, statuses: [], closed_by_server: false, connections: [],
  messages: {} };
const text = new TextDecoder();

function finish(code) {
  process.stdout.write(JSON.stringify(out) + "\n");
  process.exit(code);
}
setTimeout(() => finish(3), timeoutS * 1000).unref();

function connect() {
  const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  let opened = false;
  const client = new FoxgloveClient({ ws });
  const subTopic = new Map();
  const subEnc = new Map();
  const mine = {};
  client.on("open", () => { opened = true; out.protocol = ws.protocol; out.connections.push(mine); });
  client.on("error", (e) => {
    if (!opened && Date.now() < deadline) { setTimeout(connect, 200); return; }
    out.statuses.push(`error: ${e?.message ?? e}`);
  });
  client.on("status", (s) => out.statuses.push(s.message));
  client.on("advertise", (channels) => {
    for (const ch of channels) {
      out.channels[ch.topic] = { schemaName: ch.schemaName, encoding: ch.encoding };
      if (keep.has(ch.topic)) Object.assign(out.channels[ch.topic], { schemaEncoding: ch.schemaEncoding, schema: ch.schema });
      out.counts[ch.topic] ??= 0;
      const sub = () => { const id = client.subscribe(ch.id); subTopic.set(id, ch.topic); subEnc.set(id, ch.encoding); };
      if (afterMs > 0) setTimeout(sub, afterMs); else sub();
    }
  });
  client.on("message", ({ subscriptionId, data }) => {
    const t = subTopic.get(subscriptionId);
    if (keep.has(t)) {
      const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
      (out.messages[t] ??= []).push(subEnc.get(subscriptionId) === "json" ? text.decode(bytes)
        : Buffer.from(bytes).toString("base64"));
    }
    out.counts[t] = (out.counts[t] ?? 0) + 1;
    mine[t] = (mine[t] ?? 0) + 1;
  });
  client.on("close", () => {
    if (!opened) return; // a refused connection: retried from "error"
    if (reconnects > 0) { reconnects -= 1; setTimeout(connect, 200); return; }
    out.closed_by_server = true;
    finish(0);
  });
}
connect();
