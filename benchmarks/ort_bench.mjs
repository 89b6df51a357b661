// ONNX Runtime's CPU engine on one ONNX model: the anchor a deployment user would pick, timed as
// geo_bench times geo (batch 1, median of --iters runs after --warmup). Prints one JSON line.
//   node benchmarks/ort_bench.mjs MODEL.onnx --threads 2 --iters 15 --warmup 3 [--reference FLOAT.onnx]
// --reference: also runs FLOAT.onnx on the same input and reports how far MODEL's first output is
// from its (mean |difference| / mean |reference|): an int8 model's error.
// Preparing int8 models (benchmarks/ort_qdq.py):
//   node benchmarks/ort_bench.mjs MODEL.onnx --optimized OUT.onnx    ONNX Runtime's basic optimisation, saved
//   node benchmarks/ort_bench.mjs AUGMENTED.onnx --ranges OUT.json [--calibration 8]
//                                     the range of every output over --calibration inputs
// onnxruntime-node from the npm registry (benchmarks/vs_onnxruntime.sh installs it and passes
// its folder as GEO_ORT_DIR).
import { createRequire } from "module";
import fs from "fs";
import path from "path";
import { performance } from "perf_hooks";

// GEO_ORT_DIR: the folder whose node_modules holds onnxruntime-node (default: the current one).
const require = createRequire(path.resolve(process.env.GEO_ORT_DIR || ".", "noop.js"));
const ort = require("onnxruntime-node");

const args = process.argv.slice(2);
const opt = (name, def) => {
  const i = args.indexOf("--" + name);
  return i >= 0 ? args[i + 1] : def;
};
const model = args[0];
const threads = Number(opt("threads", 2)), iters = Number(opt("iters", 15)), warmup = Number(opt("warmup", 3));
const options = { intraOpNumThreads: threads, interOpNumThreads: 1, executionMode: "sequential", graphOptimizationLevel: "all" };

if (opt("optimized")) {
  await ort.InferenceSession.create(model, { ...options, graphOptimizationLevel: "basic", optimizedModelFilePath: opt("optimized") });
  process.exit(0);
}

const session = await ort.InferenceSession.create(model, options);
// Input k: fixed, image-like values in [0, 1) (k = 0 is what is timed).
const inputsOf = (s, k) => {
  const inputs = {};
  for (const name of s.inputNames) {
    const meta = s.inputMetadata ? s.inputMetadata.find?.((m) => m.name === name) : null;
    const shape = (meta && meta.shape) || JSON.parse(opt("shape", "[1,3,128,416]"));
    const size = shape.reduce((a, b) => a * b, 1);
    const data = new Float32Array(size);
    for (let i = 0; i < size; ++i) data[i] = ((i * 2654435761 + k * 7919) % 1000) / 1000;
    inputs[name] = new ort.Tensor("float32", data, shape);
  }
  return inputs;
};
const inputs = inputsOf(session, 0);

if (opt("ranges")) {
  const ranges = {};
  for (let k = 0; k < Number(opt("calibration", 8)); ++k) {
    const out = await session.run(inputsOf(session, k));
    for (const [name, t] of Object.entries(out)) {
      let lo = Infinity, hi = -Infinity;
      for (const v of t.data) { if (v < lo) lo = v; if (v > hi) hi = v; }
      const r = ranges[name] || [Infinity, -Infinity];
      ranges[name] = [Math.min(r[0], lo), Math.max(r[1], hi)];
    }
  }
  fs.writeFileSync(opt("ranges"), JSON.stringify(ranges));
  process.exit(0);
}

let error = null;
if (opt("reference")) {
  const reference = await ort.InferenceSession.create(opt("reference"), options);
  const name = session.outputNames[0];
  const a = (await session.run(inputs))[name].data, b = (await reference.run(inputsOf(reference, 0)))[reference.outputNames[0]].data;
  let diff = 0, size = 0;
  for (let i = 0; i < b.length; ++i) { diff += Math.abs(a[i] - b[i]); size += Math.abs(b[i]); }
  error = diff / size;
}
for (let i = 0; i < warmup; ++i) await session.run(inputs);
const times = [];
for (let i = 0; i < iters; ++i) {
  const t0 = performance.now();
  await session.run(inputs);
  times.push(performance.now() - t0);
}
const sorted = [...times].sort((a, b) => a - b);
const median = sorted.length % 2 ? sorted[(sorted.length - 1) / 2] : (sorted[sorted.length / 2 - 1] + sorted[sorted.length / 2]) / 2;
console.log(JSON.stringify({ model, onnxruntime: ort.env.versions?.common ?? "?", threads, median_ms: median,
                             times_ms: times.map((t) => Math.round(t * 100) / 100), relative_error: error }));
