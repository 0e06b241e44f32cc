"""Train a controller and verify it after every epoch; stop when VERIFIED.

A 2 -> 8 -> 8 -> 1 ReLU network learns, by plain gradient descent in
NumPy, to imitate a saturated LQR law for the double integrator of
``specs/double_integrator.ravel``. After each epoch its weights are
exported to ONNX bytes in memory (with the ``onnx`` package) and checked
with ``ravel.verify(spec, controller=onnx_bytes)`` against the reach-avoid
spec below (the spec names no controller: the bytes are it). Training stops
at the first VERIFIED epoch, and that epoch's certificate is re-checked
with ``ravel.certify``.

Run it from anywhere: ``python examples/python/train_until_verified.py``
(needs ``ravel``, ``numpy`` and ``onnx``). It exits 0 once the controller
is verified, 1 if no epoch was.
"""

import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

import ravel

SPEC = """
system double_integrator {
    state   x[2]
    control u[1]
    A = [[1, 1],
         [0, 1]]
    B = [[0.5],
         [1]]
    u in box([-1, 1])
}

initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
goal    G  = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
avoid   overshoot = { x[0] <= -2.0 } at steps [1, 5]
horizon 5

analysis {
    propagator  reach_lp
    partitioner uniform [2, 2]
    boundary    box
    samples     500
    seed        0
}
"""

A = np.array([[1.0, 1.0], [0.0, 1.0]])
B = np.array([[0.5], [1.0]])


def lqr_gain(q=1.0, r=1.0, iterations=500):
    """The discrete-time LQR gain K (u = -K x), by iterating the Riccati equation."""
    p = np.eye(2) * q
    for _ in range(iterations):
        k = np.linalg.solve(r + B.T @ p @ B, B.T @ p @ A)
        p = q * np.eye(2) + A.T @ p @ (A - B @ k)
    return k


def mlp_onnx_bytes(layers):
    """A ReLU network as ONNX bytes: `layers` is a list of (W, b) with W of
    shape (out, in); ReLU between layers, none after the last."""
    nodes, inits = [], []
    x = "input"
    for i, (w, b) in enumerate(layers):
        inits.append(numpy_helper.from_array(np.asarray(w, np.float32), f"W{i}"))
        inits.append(numpy_helper.from_array(np.asarray(b, np.float32), f"b{i}"))
        y = f"z{i}"
        nodes.append(helper.make_node("Gemm", [x, f"W{i}", f"b{i}"], [y], transB=1))
        if i + 1 < len(layers):
            nodes.append(helper.make_node("Relu", [y], [f"h{i}"]))
            y = f"h{i}"
        x = y
    n_in = np.asarray(layers[0][0]).shape[1]
    n_out = np.asarray(layers[-1][0]).shape[0]
    graph = helper.make_graph(
        nodes,
        "controller",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, [None, n_in])],
        [helper.make_tensor_value_info(x, TensorProto.FLOAT, [None, n_out])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    return model.SerializeToString()


def forward(layers, x):
    """The network on a batch of states (rows); the hidden values too."""
    hs = [x]
    for i, (w, b) in enumerate(layers):
        x = x @ w.T + b
        if i + 1 < len(layers):
            x = np.maximum(x, 0.0)
        hs.append(x)
    return hs


def train_epoch(layers, rng, k, steps=25, lr=0.02):
    """Gradient descent on the squared error to the saturated LQR law."""
    for _ in range(steps):
        x = rng.uniform([-3.5, -2.0], [3.5, 2.0], size=(256, 2))
        target = np.clip(-x @ k.T, -1.0, 1.0)
        hs = forward(layers, x)
        grad = 2.0 * (hs[-1] - target) / len(x)
        for i in reversed(range(len(layers))):
            w, b = layers[i]
            gw, gb = grad.T @ hs[i], grad.sum(axis=0)
            grad = grad @ w
            if i > 0:
                grad = grad * (hs[i] > 0)
            layers[i] = (w - lr * gw, b - lr * gb)


def main(max_epochs=40):
    rng = np.random.default_rng(0)
    k = lqr_gain()
    sizes = [2, 8, 8, 1]
    layers = [
        (rng.normal(0.0, np.sqrt(2.0 / m), size=(n, m)), np.zeros(n))
        for m, n in zip(sizes, sizes[1:])
    ]
    for epoch in range(1, max_epochs + 1):
        train_epoch(layers, rng, k)
        model = mlp_onnx_bytes(layers)
        report = ravel.verify(text=SPEC, controller=model, certificate=True)
        statuses = ", ".join(f"{p['name']} {p['status']}" for p in report["properties"])
        print(f"epoch {epoch:2d}: {report.verdict:9s} ({statuses})")
        if report.verdict == "VERIFIED":
            answer = ravel.certify(report.certificate, text=SPEC, controller=model)
            print(f"certificate: {answer['answer']}")
            print(f"final reachable box: {report.lower[-1]} .. {report.upper[-1]}")
            return 0 if answer["answer"] == "VALID" else 1
    print(f"not verified after {max_epochs} epochs")
    return 1


if __name__ == "__main__":
    sys.exit(main())
