// Pure helpers of the frame viewer's 3-D view: decode the points, orbit, project, draw into pixels.
// The server's encoding is egonet.pointcloud.encode_points: "EGP1", uint32 N, N x 3 float32 xyz
// (camera coordinates, metres: x right, y down, z forward), N x 4 uint8 (r, g, b, flags).

export const MAGIC = "EGP1";
// As egonet.pointcloud.MARK_COLORS / MARK_ALPHA, by the flags' bits (1 labelled, 2 predicted):
// labelled green, predicted red, both yellow.
export const MARKS = { 1: [40, 220, 60], 2: [230, 40, 40], 3: [250, 220, 30] };
export const MARK_ALPHA = 0.65;
export const MIN_DISTANCE = 0.05;
export const MAX_PITCH = Math.PI / 2 - 0.01;

export function decodePoints(buffer) {
  const bytes = new Uint8Array(buffer);
  if (bytes.length < 8 || String.fromCharCode(...bytes.subarray(0, 4)) !== MAGIC) {
    throw new Error("not a point cloud (EGP1)");
  }
  const count = new DataView(buffer).getUint32(4, true);
  if (bytes.length !== 8 + count * 16) throw new Error(`truncated point cloud: ${bytes.length} bytes for ${count} points`);
  // Copy the positions out: Float32Array needs 4-byte alignment and little-endian data, both true here.
  const positions = new Float32Array(buffer.slice(8, 8 + count * 12));
  const colors = new Uint8Array(buffer, 8 + count * 12, count * 4);
  return { count, positions, colors };
}

export function markColor(r, g, b, flags) {
  const mark = MARKS[flags & 3];
  if (!mark) return [r, g, b];
  return [r, g, b].map((c, i) => Math.round((1 - MARK_ALPHA) * c + MARK_ALPHA * mark[i]));
}

// The orbit's centre (the median of each axis, robust to stray far points) and a start distance.
// fov: the camera's horizontal field of view (2 atan(W / 2 fx)), so the start view frames the photograph.
export function initialView(positions, fov = Math.PI / 3) {
  const n = positions.length / 3;
  const axis = (k) => {
    const values = new Float32Array(n);
    for (let i = 0; i < n; i++) values[i] = positions[3 * i + k];
    values.sort();
    return n ? values[Math.floor(n / 2)] : 0;
  };
  const centre = [axis(0), axis(1), axis(2)];
  // From the camera's own position: the start view looks like the photograph.
  return { centre, yaw: 0, pitch: 0, distance: Math.max(Math.hypot(...centre), MIN_DISTANCE), fov };
}

export function orbit(view, dx, dy, speed = 0.01) {
  const pitch = Math.max(-MAX_PITCH, Math.min(MAX_PITCH, view.pitch - dy * speed));
  return { ...view, yaw: view.yaw + dx * speed, pitch };
}

export function zoom(view, deltaY) {
  const distance = Math.max(MIN_DISTANCE, Math.min(100, view.distance * Math.exp(deltaY * 0.001)));
  return { ...view, distance };
}

// Screen position and depth of point i: rotate about the centre (yaw about y, then pitch about x),
// move the eye back by `distance`, perspective divide. Returns null behind the eye.
export function project(view, x, y, z, width, height) {
  const px = x - view.centre[0], py = y - view.centre[1], pz = z - view.centre[2];
  const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw);
  const x1 = cy * px + sy * pz, z1 = -sy * px + cy * pz;
  const cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
  const y2 = cp * py - sp * z1, z2 = sp * py + cp * z1 + view.distance;
  if (z2 <= 1e-3) return null;
  const f = width / (2 * Math.tan(view.fov / 2));
  return { sx: width / 2 + (f * x1) / z2, sy: height / 2 + (f * y2) / z2, depth: z2 };
}

// Draw every point as a `size` x `size` square, nearest wins (a depth buffer), into RGBA `pixels`.
export function render(points, view, width, height, pixels, depth, { size = 2, background = [24, 26, 30] } = {}) {
  depth.fill(Infinity);
  for (let i = 0; i < width * height; i++) {
    pixels[4 * i] = background[0];
    pixels[4 * i + 1] = background[1];
    pixels[4 * i + 2] = background[2];
    pixels[4 * i + 3] = 255;
  }
  const { positions, colors, count } = points;
  let drawn = 0;
  for (let i = 0; i < count; i++) {
    const p = project(view, positions[3 * i], positions[3 * i + 1], positions[3 * i + 2], width, height);
    if (!p) continue;
    const x0 = Math.round(p.sx), y0 = Math.round(p.sy);
    if (x0 < 0 || y0 < 0 || x0 >= width || y0 >= height) continue;
    const color = markColor(colors[4 * i], colors[4 * i + 1], colors[4 * i + 2], colors[4 * i + 3]);
    drawn++;
    for (let dy = 0; dy < size; dy++) {
      for (let dx = 0; dx < size; dx++) {
        const x = x0 + dx, y = y0 + dy;
        if (x >= width || y >= height) continue;
        const k = y * width + x;
        if (p.depth >= depth[k]) continue;
        depth[k] = p.depth;
        pixels[4 * k] = color[0];
        pixels[4 * k + 1] = color[1];
        pixels[4 * k + 2] = color[2];
      }
    }
  }
  return drawn;
}
