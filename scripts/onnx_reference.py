#!/usr/bin/env python3
"""Optional cross-check: evaluate the committed models with onnxruntime.

Writes tests/data/onnx_reference.json, which the Rust test `onnx_models`
compares against ravel's own ONNX loader and forward pass. The product and
its tests never run Python; this script only regenerates the fixture:

    pip install onnx onnxruntime numpy
    python3 scripts/onnx_reference.py
"""
import json

import numpy as np
import onnx
import onnxruntime as ort

MODELS = [
    "double_integrator",
    "double_integrator_external",
    "double_integrator_tanh",
    "quadrotor",
    "conv_bars",
]

out = {}
rng = np.random.default_rng(0)
for name in MODELS:
    path = f"models/{name}.onnx"
    onnx.checker.check_model(onnx.load(path))
    sess = ort.InferenceSession(path)
    # the batch dimension first; an image input is fed as flat rows reshaped
    shape = [d if isinstance(d, int) else 6 for d in sess.get_inputs()[0].shape]
    n = int(np.prod(shape[1:]))
    xs = rng.uniform(-4.0, 4.0, size=(6, n)).astype(np.float32)
    ys = sess.run(None, {sess.get_inputs()[0].name: xs.reshape(shape)})[0].reshape(6, -1)
    out[name] = {
        "inputs": [[float(v) for v in x] for x in xs],
        "outputs": [[float(v) for v in y] for y in ys],
    }
with open("tests/data/onnx_reference.json", "w") as f:
    json.dump(out, f, indent=1)
    f.write("\n")
print("wrote tests/data/onnx_reference.json")
