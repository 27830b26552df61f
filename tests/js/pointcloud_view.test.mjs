import assert from "node:assert/strict";
import { test } from "node:test";

import { MIN_DISTANCE, decodePoints, initialView, markColor, orbit, project, render, zoom } from "../../static/js/pointcloud_view.js";

const close = (a, b, eps = 1e-6) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);

function encode(points) {
  // As egonet.pointcloud.encode_points: "EGP1", uint32 N, xyz float32, rgba uint8.
  const buffer = new ArrayBuffer(8 + points.length * 16);
  new Uint8Array(buffer).set([69, 71, 80, 49]);
  const data = new DataView(buffer);
  data.setUint32(4, points.length, true);
  points.forEach(([x, y, z, r, g, b, flags], i) => {
    data.setFloat32(8 + 12 * i, x, true);
    data.setFloat32(12 + 12 * i, y, true);
    data.setFloat32(16 + 12 * i, z, true);
    new Uint8Array(buffer, 8 + 12 * points.length + 4 * i, 4).set([r, g, b, flags]);
  });
  return buffer;
}

test("decodePoints reads the server's layout and refuses others", () => {
  const points = decodePoints(encode([[0.5, -0.25, 2, 10, 20, 30, 1], [0, 0, 1, 1, 2, 3, 2]]));
  assert.equal(points.count, 2);
  assert.deepEqual(Array.from(points.positions), [0.5, -0.25, 2, 0, 0, 1]);
  assert.deepEqual(Array.from(points.colors), [10, 20, 30, 1, 1, 2, 3, 2]);
  assert.throws(() => decodePoints(new ArrayBuffer(8)), /EGP1/);
  assert.throws(() => decodePoints(encode([[0, 0, 1, 0, 0, 0, 0]]).slice(0, 20)), /truncated/);
});

test("marks blend like egonet.pointcloud.marked_colors", () => {
  assert.deepEqual(markColor(100, 100, 100, 0), [100, 100, 100]);
  assert.deepEqual(markColor(100, 100, 100, 1), [Math.round(35 + 0.65 * 40), Math.round(35 + 0.65 * 220), Math.round(35 + 0.65 * 60)]);
  assert.deepEqual(markColor(0, 0, 0, 3), [Math.round(0.65 * 250), Math.round(0.65 * 220), Math.round(0.65 * 30)]);
});

test("the start view is the camera's: a point on the optical axis lands in the middle", () => {
  const positions = new Float32Array([0, 0, 2, 0.1, 0, 2, 0, 0.1, 2]);
  const view = initialView(positions);
  assert.deepEqual(view.centre, [0, 0, 2]);
  close(view.distance, 2);
  const p = project(view, 0, 0, 2, 200, 100);
  close(p.sx, 100);
  close(p.sy, 50);
  close(p.depth, 2);
  // x right and y down stay right and down on the screen.
  assert.ok(project(view, 0.1, 0, 2, 200, 100).sx > 100 && project(view, 0, 0.1, 2, 200, 100).sy > 50);
});

test("orbiting a quarter turn brings a point on +x to the centre line, nearer or farther", () => {
  const view = { centre: [0, 0, 0], yaw: 0, pitch: 0, distance: 5, fov: Math.PI / 3 };
  const turned = orbit(view, Math.PI / 2 / 0.01, 0);
  close(turned.yaw, Math.PI / 2);
  const p = project(turned, 1, 0, 0, 100, 100);
  close(p.sx, 50, 1e-4);
  close(p.depth, 4, 1e-6); // rotated onto -z: one metre nearer the eye
  assert.ok(orbit(view, 0, 1e6).pitch < Math.PI / 2); // the pitch stops short of the pole
  assert.equal(project({ ...view, distance: 0.5 }, 0, 0, -1, 100, 100), null); // behind the eye
});

test("zoom is multiplicative and bounded", () => {
  const view = { distance: 1 };
  close(zoom(view, 1000).distance, Math.E);
  assert.equal(zoom(view, -1e6).distance, MIN_DISTANCE);
});

test("render draws nearer points over farther ones", () => {
  const points = decodePoints(encode([[0, 0, 3, 255, 0, 0, 0], [0, 0, 2, 0, 0, 255, 0], [5, 5, 2, 0, 255, 0, 0]]));
  const view = { centre: [0, 0, 2], yaw: 0, pitch: 0, distance: 2, fov: Math.PI / 3 };
  const pixels = new Uint8ClampedArray(20 * 20 * 4);
  const depth = new Float32Array(20 * 20);
  assert.equal(render(points, view, 20, 20, pixels, depth, { size: 1 }), 2); // the third is off screen
  const k = 10 * 20 + 10;
  assert.deepEqual(Array.from(pixels.subarray(4 * k, 4 * k + 4)), [0, 0, 255, 255]); // the nearer, blue one
  assert.deepEqual(Array.from(pixels.subarray(0, 4)), [24, 26, 30, 255]);
});
