import assert from "node:assert/strict";
import { test } from "node:test";

import { api, ApiError } from "../../static/js/api.js";

function fakeFetch(status, body) {
  const calls = [];
  const impl = async (url, init) => {
    calls.push({ url, init });
    return {
      ok: status < 400,
      status,
      headers: { get: () => "application/json" },
      json: async () => body,
    };
  };
  return { impl, calls };
}

test("sends JSON and returns the parsed body", async () => {
  const { impl, calls } = fakeFetch(200, { ok: 1 });
  const result = await api("POST", "/api/x", { a: 1 }, { fetchImpl: impl });
  assert.deepEqual(result, { ok: 1 });
  assert.equal(calls[0].init.body, '{"a":1}');
  assert.equal(calls[0].init.headers["Content-Type"], "application/json");
  assert.ok("X-CSRFToken" in calls[0].init.headers);
});

test("errors carry the server's message and fields", async () => {
  const { impl } = fakeFetch(409, { error: "conflict", message: "stale version", fields: { version: "is 3" } });
  await assert.rejects(api("PUT", "/api/x", {}, { fetchImpl: impl }), (err) => {
    assert.ok(err instanceof ApiError);
    assert.equal(err.status, 409);
    assert.equal(err.message, "stale version");
    assert.equal(err.body.fields.version, "is 3");
    return true;
  });
});
