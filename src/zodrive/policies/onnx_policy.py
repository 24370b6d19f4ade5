"""ONNX policies: export a model's acting network, and run an ONNX file as a victim.

`export_onnx` writes the Q-network (DQN) or actor (DDPG) rebuilt by the safe loader, with a
flatten in front, so the file's contract is observations (B, vehicles, features) -> outputs
(B, k); the metadata records kind, observation shape, number of outputs, algorithm and the
source zip's SHA-256. `onnx_victim` serves such a file through onnxruntime: a real serving
runtime behind the same query function every attack uses, and a format with no pickle in it.
Needs the optional extra `zodrive[onnx]` (onnx, onnxruntime).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

SUFFIX = ".onnx"


def is_onnx(model: str | Path) -> bool:
    return str(model).lower().endswith(SUFFIX)


def _require(module: str) -> Any:
    try:
        return __import__(module)
    except ImportError:
        raise ZodriveError(f"ONNX support needs {module}: pip install 'zodrive[onnx]'") from None


def export_onnx(model: str, out: Path) -> Path:
    """Write `model`'s acting network (safely rebuilt, nothing unpickled) to `out` (.onnx)."""
    import torch

    from zodrive.policies.loading import inspect_model, load_network, model_file, raw_network_only
    from zodrive.runinfo import sha256

    if not str(out).endswith(SUFFIX):
        raise ZodriveError(f"--out must end in {SUFFIX}: {out}")
    from zodrive.policies.factory import is_factory

    if is_factory(model) or str(model).startswith("baseline:") or is_onnx(model):
        raise ZodriveError(f"export writes an SB3 model's network as ONNX; {model} is not an SB3 zip or model folder "
                           "(a policy in your own code: export it with torch.onnx.export)")
    file = model_file(model)
    info = inspect_model(file)  # a file that is no model is said so before any extra is asked for
    raw_network_only(model, "export")
    network = load_network(file)
    onnx = _require("onnx")
    net = torch.nn.Sequential(torch.nn.Flatten(), network.net).eval()
    dummy = torch.zeros(1, *network.obs_shape)
    out.parent.mkdir(parents=True, exist_ok=True)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter is deprecated but needs no onnxscript
        torch.onnx.export(net, (dummy,), str(out), input_names=["obs"], output_names=["out"],
                          dynamic_axes={"obs": {0: "batch"}, "out": {0: "batch"}}, dynamo=False)
    proto = onnx.load(str(out))
    meta = {"zodrive_kind": info["kind"], "zodrive_algo": info["algo"],
            "zodrive_obs_shape": json.dumps(list(network.obs_shape)), "zodrive_n_outputs": str(info["n_actions"]),
            "zodrive_source_sha256": sha256(file)}
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(proto, str(out))
    return out


def _session(path: Path) -> Any:
    """An onnxruntime session on CPU, graph optimizations off so that the arithmetic stays that
    of the exported network, one thread (small MLPs)."""
    ort = _require("onnxruntime")
    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    options.intra_op_num_threads = 1
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 - onnxruntime raises many types for a bad file
        raise ZodriveError(f"{path} is not a readable ONNX model: {exc}") from None


def _contract(session: Any, path: Path) -> dict[str, Any]:
    meta = session.get_modelmeta().custom_metadata_map
    if "zodrive_kind" not in meta:
        raise ZodriveError(f"{path} has no zodrive contract in its metadata (export it with `zodrive export`)")
    return {"kind": meta["zodrive_kind"], "algo": meta["zodrive_algo"],
            "obs_shape": tuple(json.loads(meta["zodrive_obs_shape"])), "n_actions": int(meta["zodrive_n_outputs"])}


def onnx_metadata(path: Path) -> dict[str, Any]:
    """The contract stored in a zodrive ONNX file (kind, obs_shape, n_actions, algo)."""
    return _contract(_session(path), path)


def onnx_victim(path: Path, preset: dict[str, Any] | None = None) -> Victim:
    """An ONNX file as a black-box victim (one onnxruntime session); with `preset`, checked
    to fit it."""
    session = _session(path)
    meta = _contract(session, path)
    if preset is not None:
        from zodrive.policies.loading import check_fits

        check_fits(meta, preset, path)

    def query(batch: np.ndarray) -> np.ndarray:
        obs = np.ascontiguousarray(batch, dtype=np.float32).reshape(-1, *meta["obs_shape"])
        return session.run(None, {"obs": obs})[0]

    return Victim(query=query, kind=meta["kind"], obs_shape=meta["obs_shape"])
