// ONNX Runtime's CPU engine on one ONNX model: the anchor a deployment user would pick, timed as
// geo_bench times geo (batch 1, median of --iters runs after --warmup). Prints one JSON line.
//   node scripts/ort_bench.mjs MODEL.onnx --threads 2 --iters 15 --warmup 3
// onnxruntime-node from the npm registry (scripts/bench_vs_onnxruntime.sh installs it and passes
// its folder as GEO_ORT_DIR).
import { createRequire } from "module";
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
const session = await ort.InferenceSession.create(model, {
  intraOpNumThreads: threads,
  interOpNumThreads: 1,
  executionMode: "sequential",
  graphOptimizationLevel: "all",
});
const inputs = {};
for (const name of session.inputNames) {
  const meta = session.inputMetadata ? session.inputMetadata.find?.((m) => m.name === name) : null;
  const shape = (meta && meta.shape) || JSON.parse(opt("shape", "[1,3,128,416]"));
  const size = shape.reduce((a, b) => a * b, 1);
  const data = new Float32Array(size);
  for (let i = 0; i < size; ++i) data[i] = ((i * 2654435761) % 1000) / 1000;  // fixed, image-like values
  inputs[name] = new ort.Tensor("float32", data, shape);
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
                             times_ms: times.map((t) => Math.round(t * 100) / 100) }));
