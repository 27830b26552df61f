import assert from "node:assert/strict";
import { test } from "node:test";

import { api, ApiError, CSRF_TOKEN_URL, request } from "../../static/js/api.js";

function answer(status, body) {
  return {
    ok: status < 400,
    status,
    headers: { get: () => "application/json" },
    json: async () => body,
  };
}

function fakeFetch(status, body) {
  const calls = [];
  const impl = async (url, init) => {
    calls.push({ url, init });
    return answer(status, body);
  };
  return { impl, calls };
}

// A page whose meta tag holds `token`, and a server that accepts only `current`.
function stalePage(token, current) {
  const meta = { content: token };
  const doc = { querySelector: (selector) => (selector === 'meta[name="csrf-token"]' ? meta : null) };
  const calls = [];
  const impl = async (url, init) => {
    calls.push({ url, method: init.method, token: init.headers["X-CSRFToken"] });
    await new Promise((r) => setImmediate(r));
    if (url === CSRF_TOKEN_URL) return answer(200, { csrf_token: current });
    if (init.headers["X-CSRFToken"] !== current) return answer(400, { error: "csrf", message: "The CSRF tokens do not match.", fields: {} });
    return answer(200, { saved: url });
  };
  return { meta, doc, calls, impl };
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

test("a request refused for its CSRF token fetches a fresh one and is sent again", async () => {
  const page = stalePage("stale", "fresh");
  const result = await api("PUT", "/api/save", { a: 1 }, { fetchImpl: page.impl, doc: page.doc });
  assert.deepEqual(result, { saved: "/api/save" });
  assert.equal(page.meta.content, "fresh", "the meta tag holds the fresh token");
  assert.deepEqual(
    page.calls.map((c) => [c.method, c.url, c.token]),
    [
      ["PUT", "/api/save", "stale"],
      ["GET", CSRF_TOKEN_URL, undefined],
      ["PUT", "/api/save", "fresh"],
    ],
  );
});

test("requests refused together share one token request", async () => {
  const page = stalePage("stale", "fresh");
  const options = { fetchImpl: page.impl, doc: page.doc };
  await Promise.all([api("PUT", "/api/a", {}, options), api("POST", "/api/b", {}, options)]);
  assert.equal(page.calls.filter((c) => c.url === CSRF_TOKEN_URL).length, 1);
  assert.deepEqual(page.calls.filter((c) => c.token === "fresh").map((c) => c.url).sort(), ["/api/a", "/api/b"]);
});

test("the CSRF retry happens once, and only for CSRF refusals", async () => {
  const page = stalePage("stale", "fresh");
  page.impl = async (url, init) => {
    page.calls.push({ url, token: init.headers["X-CSRFToken"] });
    return url === CSRF_TOKEN_URL ? answer(200, { csrf_token: "fresh" }) : answer(400, { error: "csrf", message: "The CSRF token is invalid." });
  };
  await assert.rejects(api("PUT", "/api/x", {}, { fetchImpl: page.impl, doc: page.doc }), (err) => err.status === 400 && err.body.error === "csrf");
  assert.equal(page.calls.length, 3, "the request, the token, the request once more");

  const { impl, calls } = fakeFetch(400, { error: "bad_request", message: "mask: bad RLE", fields: { mask: "bad RLE" } });
  await assert.rejects(api("PUT", "/api/x", {}, { fetchImpl: impl }), (err) => err.message === "mask: bad RLE");
  assert.equal(calls.length, 1, "another 400 is not sent again");
});

test("a server that cannot be reached is an ApiError with status 0, in words", async () => {
  const impl = async () => {
    throw new TypeError("Failed to fetch");
  };
  await assert.rejects(api("PUT", "/api/x", {}, { fetchImpl: impl }), (err) => {
    assert.ok(err instanceof ApiError);
    assert.equal(err.status, 0);
    assert.equal(err.message, "the server could not be reached");
    return true;
  });
});

test("an error that is not JSON still says what happened", async () => {
  const impl = async () => ({ ok: false, status: 502, headers: { get: () => "text/html" }, json: async () => assert.fail("not JSON") });
  await assert.rejects(api("GET", "/api/x", undefined, { fetchImpl: impl }), (err) => err.status === 502 && err.message === "the server answered HTTP 502");
});

test("request gives the response itself; GET sends no token; keepalive only for small bodies", async () => {
  const { impl, calls } = fakeFetch(200, {});
  const response = await request("GET", "/m.png", undefined, { fetchImpl: impl, cache: "no-cache", headers: { Accept: "image/png" } });
  assert.equal(response.status, 200);
  assert.equal(calls[0].init.cache, "no-cache");
  assert.equal(calls[0].init.headers.Accept, "image/png");
  assert.ok(!("X-CSRFToken" in calls[0].init.headers));
  await request("POST", "/t", { s: 1 }, { fetchImpl: impl, keepalive: true });
  assert.equal(calls[1].init.keepalive, true);
  await request("PUT", "/big", { s: "x".repeat(70000) }, { fetchImpl: impl, keepalive: true });
  assert.equal(calls[2].init.keepalive, undefined, "browsers refuse keepalive bodies over 64 KiB");
});
