// Runs a TF.js graph model with TensorFlow.js itself (tfjs-converter + the pure
// JavaScript CPU backend), the independent reference for scripts/tools/tfjs_to_onnx.py.
//
//   NODE_PATH=<node_modules> node tfjs_reference.js MODEL.json INPUT.f32 OUT_DIR
// INPUT.f32: raw little-endian float32 in the model's input shape (from its signature).
// Writes OUT_DIR/<output name without ":0">.f32 per signature output and
// OUT_DIR/outputs.json ({name: shape}).
'use strict';
const fs = require('fs');
const path = require('path');
const tf = require('@tensorflow/tfjs-core');
require('@tensorflow/tfjs-backend-cpu');
const converter = require('@tensorflow/tfjs-converter');

async function main() {
  const [modelJson, inputFile, outDir] = process.argv.slice(2);
  if (!outDir) {
    console.error('usage: tfjs_reference.js MODEL.json INPUT.f32 OUT_DIR');
    process.exit(2);
  }
  await tf.setBackend('cpu');
  const model = JSON.parse(fs.readFileSync(modelJson, 'utf8'));
  const weightSpecs = [];
  const buffers = [];
  for (const group of model.weightsManifest) {
    weightSpecs.push(...group.weights);
    for (const p of group.paths) buffers.push(fs.readFileSync(path.join(path.dirname(modelJson), p)));
  }
  const all = Buffer.concat(buffers);
  const weightData = all.buffer.slice(all.byteOffset, all.byteOffset + all.byteLength);
  const graph = await converter.loadGraphModel(tf.io.fromMemory({
    modelTopology: model.modelTopology, weightSpecs, weightData,
    format: model.format, generatedBy: model.generatedBy, convertedBy: model.convertedBy,
    signature: model.signature}));
  const inSig = Object.values(model.signature.inputs)[0];
  const shape = inSig.tensorShape.dim.map((d) => parseInt(d.size, 10));
  const raw = fs.readFileSync(inputFile);
  const data = new Float32Array(raw.buffer.slice(raw.byteOffset, raw.byteOffset + raw.byteLength));
  const input = tf.tensor(data, shape, 'float32');
  const names = Object.keys(model.signature.outputs);
  const t0 = Date.now();
  const outs = graph.execute({[inSig.name]: input}, names);
  const shapes = {};
  fs.mkdirSync(outDir, {recursive: true});
  for (let i = 0; i < names.length; ++i) {
    const base = names[i].split(':')[0];
    fs.writeFileSync(path.join(outDir, base + '.f32'), Buffer.from((await outs[i].data()).buffer));
    shapes[base] = outs[i].shape;
  }
  fs.writeFileSync(path.join(outDir, 'outputs.json'), JSON.stringify(shapes));
  console.log(`tfjs ${tf.version_core} (${tf.getBackend()}): ${names.length} outputs in ${Date.now() - t0} ms`);
}

main().catch((e) => { console.error(e); process.exit(1); });
