// Calls to the JSON API: the CSRF token from the page's meta tag goes in a
// header, and errors come back as ApiError carrying the server's
// {error, message, fields} body.

export class ApiError extends Error {
  constructor(status, body) {
    super(body?.message || `HTTP ${status}`);
    this.status = status;
    this.body = body || {};
  }
}

export function csrfToken(doc = globalThis.document) {
  return doc?.querySelector('meta[name="csrf-token"]')?.content ?? "";
}

// api("POST", "/api/x", {a: 1}) -> parsed JSON; body may also be a Blob/FormData.
export async function api(method, url, body, { headers = {}, fetchImpl = globalThis.fetch } = {}) {
  const init = { method, headers: { Accept: "application/json", ...headers }, credentials: "same-origin" };
  if (method !== "GET" && method !== "HEAD") init.headers["X-CSRFToken"] = csrfToken();
  if (body instanceof Blob || body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetchImpl(url, init);
  const type = response.headers.get("Content-Type") || "";
  const data = type.includes("application/json") ? await response.json() : null;
  if (!response.ok) throw new ApiError(response.status, data);
  return data;
}
