// Calls to the server: the CSRF token from the page's meta tag goes in a
// header, and errors come back as ApiError carrying the server's
// {error, message, fields} body.
//
// A token can go stale while the page is open (signed out and in again in
// another tab, the server restarted with another key): a request refused for
// its token ({"error": "csrf"}) fetches a fresh one, puts it in the meta
// tag, and is sent once more. A request that reaches no server fails with
// status 0 and says so in words.

export const CSRF_TOKEN_URL = "/api/csrf-token";
// Browsers refuse keepalive requests with bodies over 64 KiB.
const KEEPALIVE_LIMIT = 60000;

export class ApiError extends Error {
  constructor(status, body) {
    super(body?.message || `the server answered HTTP ${status}`);
    this.status = status;
    this.body = body || {};
  }
}

export function csrfToken(doc = globalThis.document) {
  return doc?.querySelector('meta[name="csrf-token"]')?.content ?? "";
}

let refreshing = null; // one token request at a time, shared by the requests waiting for it

// Ask the server for the session's token and put it in the meta tag.
export function refreshCsrfToken({ fetchImpl = globalThis.fetch, doc = globalThis.document } = {}) {
  refreshing ??= (async () => {
    const data = await api("GET", CSRF_TOKEN_URL, undefined, { fetchImpl, doc });
    const meta = doc?.querySelector('meta[name="csrf-token"]');
    if (meta) meta.content = data.csrf_token;
    return data.csrf_token;
  })().finally(() => (refreshing = null));
  return refreshing;
}

async function send(method, url, body, init, fetchImpl) {
  try {
    const response = await fetchImpl(url, { method, body, credentials: "same-origin", ...init });
    if (!response.ok) throw new ApiError(response.status, await json(response).catch(() => null));
    return response;
  } catch (err) {
    if (err instanceof ApiError) throw err;
    throw new ApiError(0, { error: "network", message: "the server could not be reached" });
  }
}

async function json(response) {
  const type = response.headers.get("Content-Type") || "";
  return type.includes("application/json") ? response.json() : null;
}

// request("PUT", url, body) -> the Response (ok); body: JSON-able, Blob or FormData.
// Options: headers, cache, keepalive (the request may outlive the page).
export async function request(method, url, body, { headers = {}, cache, keepalive = false, fetchImpl = globalThis.fetch, doc = globalThis.document } = {}) {
  const changes = method !== "GET" && method !== "HEAD";
  const init = { headers: { Accept: "application/json", ...headers } };
  let payload = body;
  if (body !== undefined && !(body instanceof Blob || body instanceof FormData)) {
    init.headers["Content-Type"] = "application/json";
    payload = JSON.stringify(body);
  }
  if (cache) init.cache = cache;
  const size = typeof payload === "string" ? payload.length : (payload?.size ?? 0);
  if (keepalive && size < KEEPALIVE_LIMIT) init.keepalive = true;
  // The token is read at each attempt: the retry sends the fresh one.
  const attempt = () =>
    send(method, url, payload, changes ? { ...init, headers: { ...init.headers, "X-CSRFToken": csrfToken(doc) } } : init, fetchImpl);
  try {
    return await attempt();
  } catch (err) {
    if (!changes || err.status !== 400 || err.body.error !== "csrf") throw err;
    await refreshCsrfToken({ fetchImpl, doc });
    return attempt();
  }
}

// api("POST", "/api/x", {a: 1}) -> parsed JSON (null when the answer is not JSON).
export async function api(method, url, body, options = {}) {
  return json(await request(method, url, body, options));
}
