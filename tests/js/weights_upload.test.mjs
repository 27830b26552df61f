import assert from "node:assert/strict";
import { test } from "node:test";

import { chunkRanges, formatBytes, uploadWeights } from "../../static/js/weights_upload.js";

test("chunkRanges covers the file exactly, the last chunk short", () => {
  assert.deepEqual(chunkRanges(10, 4), [[0, 4], [4, 8], [8, 10]]);
  assert.deepEqual(chunkRanges(8, 4), [[0, 4], [4, 8]]);
  assert.deepEqual(chunkRanges(0, 4), []);
  assert.throws(() => chunkRanges(10, 0), RangeError);
});

test("formatBytes says megabytes", () => {
  assert.equal(formatBytes(12_500_000, 270_000_000), "12.5 of 270.0 MB");
});

// A server keeping the bytes it was sent; it loses the answer to the second chunk once.
function server({ chunk = 4, finish = { run_id: 7, release: "rgb", message: "queued" } } = {}) {
  const received = [];
  const calls = [];
  let lost = false;
  const reply = (status, body) => ({ ok: status < 400, status, headers: { get: () => "application/json" }, json: async () => body });
  const impl = async (url, init) => {
    calls.push(`${init.method} ${url}`);
    if (init.method === "POST" && url.endsWith("/uploads")) return reply(201, { upload: "abc", chunk_bytes: chunk });
    if (init.method === "PUT") {
      const offset = Number(new URL(url, "http://x").searchParams.get("offset"));
      if (offset > received.length) return reply(409, { error: "conflict", received: received.length });
      const bytes = new Uint8Array(await init.body.arrayBuffer());
      received.splice(offset, bytes.length, ...bytes);
      if (offset === chunk && !lost) {
        lost = true;
        throw new TypeError("network down");
      }
      return reply(200, { received: received.length });
    }
    if (url.endsWith("/finish")) return reply(201, finish);
    return reply(204, null);
  };
  return { impl, received, calls };
}

test("uploadWeights sends every byte once in order, retries a lost answer, then finishes", async () => {
  const bytes = Uint8Array.from({ length: 10 }, (_, i) => i * 3);
  const file = new File([bytes], "EgoNet.caffemodel");
  const { impl, received, calls } = server();
  const seen = [];
  const answer = await uploadWeights(file, { base: "/training/weights", fetchImpl: impl, onProgress: (s, t) => seen.push([s, t]) });
  assert.deepEqual(received, [...bytes]);
  assert.equal(answer.run_id, 7);
  assert.deepEqual(seen.at(-1), [10, 10]);
  assert.ok(calls.includes("POST /training/weights/uploads/abc/finish"));
  assert.equal(calls.filter((c) => c.startsWith("PUT")).length, 4); // 3 chunks, one sent twice
});

test("a refused file is reported and the upload removed", async () => {
  const file = new File([new Uint8Array(3)], "x.caffemodel");
  const { impl, calls } = server();
  const refusing = async (url, init) => {
    if (url.endsWith("/finish")) {
      calls.push(`${init.method} ${url}`);
      return { ok: false, status: 400, headers: { get: () => "application/json" }, json: async () => ({ error: "bad_request", message: "not the authors' RGB+DHG release" }) };
    }
    return impl(url, init);
  };
  await assert.rejects(uploadWeights(file, { base: "/t", fetchImpl: refusing }), /not the authors/);
  assert.equal(calls.at(-1), "DELETE /t/uploads/abc");
});
