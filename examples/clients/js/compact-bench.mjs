// Times the compact decoder on the 71-joint test vector (docs/compact-frames/chain71.json):
// node examples/clients/js/compact-bench.mjs
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { join, dirname } from "node:path";

import { CompactDecoder, fromHex } from "./compact.mjs";

const path = join(dirname(fileURLToPath(import.meta.url)), "../../../docs/compact-frames/chain71.json");
const vector = JSON.parse(readFileSync(path, "utf8"));
const [key, delta] = vector.frames.map((f) => fromHex(f.hex));
const decoder = new CompactDecoder(vector.layout);

function run(frames) {
  const start = process.hrtime.bigint();
  for (let i = 0; i < frames; i++) {
    decoder.decode(key);
    decoder.decode(delta);
  }
  return Number(process.hrtime.bigint() - start) / 1e3 / (2 * frames);
}

run(20000); // warm up the JIT
const samples = [1, 2, 3, 4, 5].map(() => run(50000)).sort((a, b) => a - b);
console.log(
  `71 joints, ${key.length} B key / ${delta.length} B delta: ` +
    `${samples[2].toFixed(2)} µs per frame (median of 5 runs of 100,000 frames; min ${samples[0].toFixed(2)})`,
);
