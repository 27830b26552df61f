// Binary masks as run lengths.
//
// A mask is a Uint8Array of width * height values, 0 or 1, row by row.
//
// * COCO's RLE (what the server stores and pycocotools reads) runs down the
//   columns (column-major), starts with a run of 0s, and compresses the
//   counts into a string: each count (from the fourth on, as the difference
//   to the count two places before) in 5-bit groups, least significant
//   first, 6 bits per character offset by 48, bit 0x20 = "more groups",
//   bit 0x10 of the last group = sign.
// * Row runs (encodeRuns / decodeRuns) are the same idea row by row, kept
//   as a Uint32Array: a compact snapshot for the undo history.

export function countsToString(counts) {
  let out = "";
  for (let i = 0; i < counts.length; i++) {
    let x = counts[i];
    if (i > 2) x -= counts[i - 2];
    let more = true;
    while (more) {
      // Arithmetic (not bitwise) so values past 2^31 stay exact.
      let c = ((x % 32) + 32) % 32;
      x = (x - c) / 32;
      more = c & 0x10 ? x !== -1 : x !== 0;
      if (more) c |= 0x20;
      out += String.fromCharCode(c + 48);
    }
  }
  return out;
}

export function stringToCounts(text) {
  const counts = [];
  let p = 0;
  while (p < text.length) {
    let x = 0;
    let k = 0;
    let more = true;
    while (more) {
      if (p >= text.length) throw new Error("RLE string ends inside a number");
      const c = text.charCodeAt(p) - 48;
      if (c < 0 || c > 63) throw new Error(`character ${JSON.stringify(text[p])} is not part of COCO's RLE alphabet`);
      x += (c & 0x1f) * 2 ** (5 * k);
      more = (c & 0x20) !== 0;
      p++;
      k++;
      if (!more && c & 0x10) x -= 2 ** (5 * k);
    }
    if (counts.length > 2) x += counts[counts.length - 2];
    counts.push(x);
  }
  return counts;
}

// Column-major run lengths of a row-major mask, starting with 0s.
export function columnCounts(mask, width, height) {
  const counts = [];
  let value = 0;
  let run = 0;
  for (let x = 0; x < width; x++) {
    for (let i = x; i < width * height; i += width) {
      if (mask[i] !== value) {
        counts.push(run);
        run = 0;
        value = mask[i];
      }
      run++;
    }
  }
  counts.push(run);
  return counts;
}

export function encodeCocoRle(mask, width, height) {
  if (mask.length !== width * height) throw new Error(`mask has ${mask.length} values, expected ${width * height}`);
  return { size: [height, width], counts: countsToString(columnCounts(mask, width, height)) };
}

export function decodeCocoRle(rle) {
  const [height, width] = rle.size;
  const counts = typeof rle.counts === "string" ? stringToCounts(rle.counts) : rle.counts;
  const total = counts.reduce((a, b) => a + b, 0);
  if (total !== width * height) throw new Error(`RLE covers ${total} pixels, the mask has ${width * height}`);
  const mask = new Uint8Array(width * height);
  let j = 0; // position in column-major order
  counts.forEach((count, k) => {
    if (k % 2 === 1) {
      for (let t = j; t < j + count; t++) {
        const x = Math.floor(t / height);
        mask[(t - x * height) * width + x] = 1;
      }
    }
    j += count;
  });
  return mask;
}

// Row-major runs, starting with 0s: a compact copy for undo snapshots.
export function encodeRuns(mask) {
  const runs = [];
  let value = 0;
  let run = 0;
  for (let i = 0; i < mask.length; i++) {
    if (mask[i] !== value) {
      runs.push(run);
      run = 0;
      value = mask[i];
    }
    run++;
  }
  runs.push(run);
  return Uint32Array.from(runs);
}

export function decodeRuns(runs, length) {
  const mask = new Uint8Array(length);
  let i = 0;
  for (let k = 0; k < runs.length; k++) {
    if (k % 2 === 1) mask.fill(1, i, i + runs[k]);
    i += runs[k];
  }
  if (i !== length) throw new Error(`runs cover ${i} values, expected ${length}`);
  return mask;
}

// A mask from RGBA pixels (a decoded PNG): on where the red channel is bright.
export function maskFromRGBA(data, length) {
  const mask = new Uint8Array(length);
  for (let i = 0; i < length; i++) mask[i] = data[4 * i] > 127 ? 1 : 0;
  return mask;
}
