// Sending a released .caffemodel (hundreds of MB) to the server in chunks:
// announce it, PUT each slice at its offset (each request stays far under
// the server's request limit, and a chunk whose answer was lost is sent
// again at the offset the server reports), then ask the server to register
// it; the worker converts it and the runs table shows its progress.
import { api, ApiError, request } from "./api.js";

// [start, end) byte ranges of a file of `size` bytes in chunks of `chunk` bytes.
export function chunkRanges(size, chunk) {
  if (!(chunk > 0)) throw new RangeError("chunk must be a positive number of bytes");
  const ranges = [];
  for (let start = 0; start < size; start += chunk) ranges.push([start, Math.min(size, start + chunk)]);
  return ranges;
}

// "12.5 of 270.0 MB"
export function formatBytes(done, total) {
  const mb = (n) => (n / 1e6).toFixed(1);
  return `${mb(done)} of ${mb(total)} MB`;
}

// Upload `file` (a File or Blob with a name); onProgress(sentBytes, totalBytes).
// Returns the server's answer to "finish" ({run_id, release, message}).
export async function uploadWeights(file, { base, name = null, width = 641, height = 481, onProgress = () => {}, retries = 2, fetchImpl } = {}) {
  const options = fetchImpl ? { fetchImpl } : {};
  const start = await api("POST", `${base}/uploads`, { filename: file.name, size: file.size }, options);
  const url = `${base}/uploads/${start.upload}`;
  try {
    let offset = 0;
    let failures = 0;
    while (offset < file.size) {
      const end = Math.min(file.size, offset + start.chunk_bytes);
      try {
        const answer = await api("PUT", `${url}?offset=${offset}`, file.slice(offset, end), options);
        offset = answer.received;
        failures = 0;
      } catch (err) {
        // The server says how much it has (a retried chunk, a lost answer): go on from there.
        if (err instanceof ApiError && err.status === 409 && Number.isInteger(err.body.received)) offset = err.body.received;
        else if (err.status === 0 && failures < retries) failures += 1;
        else throw err;
      }
      onProgress(offset, file.size);
    }
    return await api("POST", `${url}/finish`, { name, width, height }, options);
  } catch (err) {
    if (err.status !== 404) await request("DELETE", url, undefined, options).catch(() => {});
    throw err;
  }
}
