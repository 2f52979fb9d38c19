"""A YOLOX detector's ONNX graph as a trainable PyTorch module, and its weights written back into that graph.

The shipped YOLOX-Nano (Megvii YOLOX, Apache-2.0; ``MANIFEST.md`` of the shared data) is an ONNX graph whose batch
norms are folded into its convolutions. Rather than re-writing the architecture, :class:`OnnxYolox` interprets the
graph node by node (the ten operators it uses: Conv, Sigmoid, Mul, Add, Concat, Slice, MaxPool, Resize, Reshape,
Transpose), each Conv an ``nn.Conv2d`` initialised from the graph's own initializers, so the module computes exactly
what onnxruntime does (the parity is checked after export, :func:`aerodaas.training.export.export_checked`).

The head is cut before its last sigmoids: :meth:`OnnxYolox.forward` returns per stride (8, 16, 32) the raw
``(B, 5 + nc, H/s, W/s)`` map -- box ``(dx, dy, log w, log h)``, objectness logit, ``nc`` class logits -- what the
losses want. :func:`write_onnx` writes trained weights back into a copy of the graph, with the class convolutions
resized to ``nc`` and the output made ``(B, A, 5 + nc)`` with a dynamic batch and input size (the layout
:class:`aerodaas.perception.detect.YoloxDetector` decodes), and the class names in the model's metadata.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import onnx
import torch
from onnx import helper, numpy_helper
from torch import nn
from torch.nn import functional as F

__all__ = ["OnnxYolox", "HeadConvs", "write_onnx", "STRIDES"]

STRIDES = (8, 16, 32)
_HEAD = ("cls_preds", "reg_preds", "obj_preds")


@dataclass(frozen=True)
class HeadConvs:
    """The names of one stride's three output convolutions and of the Concat that joins them in the graph."""

    reg: str
    obj: str
    cls: str
    concat: str


def _attrs(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _conv_from_node(node: onnx.NodeProto, weights: dict[str, np.ndarray]) -> nn.Conv2d:
    a = _attrs(node)
    w = weights[node.input[1]]
    out_ch, in_per_group, kh, kw = w.shape
    group = int(a.get("group", 1))
    pads = a.get("pads", [0, 0, 0, 0])
    if pads[0] != pads[2] or pads[1] != pads[3]:
        raise ValueError(f"Conv {node.output[0]}: asymmetric pads {pads} are not supported")
    conv = nn.Conv2d(in_per_group * group, out_ch, (kh, kw), stride=tuple(a.get("strides", [1, 1])),
                     padding=(pads[0], pads[1]), dilation=tuple(a.get("dilations", [1, 1])), groups=group,
                     bias=len(node.input) > 2)
    with torch.no_grad():
        conv.weight.copy_(torch.from_numpy(w.copy()))
        if conv.bias is not None:
            conv.bias.copy_(torch.from_numpy(weights[node.input[2]].copy()))
    return conv


class OnnxYolox(nn.Module):
    """A YOLOX ONNX graph (``(1, 3, H, W)`` BGR 0-255 in, ``(1, A, 5 + nc)`` out) as a trainable module.

    Args:
        path: the ONNX file (a YOLOX export with the ``head.{cls,reg,obj}_preds.{0,1,2}`` convolutions).
        class_rows: the model's class rows to keep, in the new output order (e.g. ``[2, 7, 0]`` takes COCO's car,
            truck and person as classes 0, 1, 2 -- fine-tuning starts from what the model already knows); ``None``
            keeps every class.

    ``forward(x)`` takes ``(B, 3, H, W)`` float32 BGR 0-255 (H, W multiples of 32) and returns three tensors
    ``(B, 5 + nc, H/s, W/s)`` for strides 8, 16, 32 (raw: no sigmoid). Raises ValueError for a graph this
    interpreter does not support (an unknown operator, no YOLOX head) or a class row out of range.
    """

    def __init__(self, path: str | os.PathLike, class_rows: Sequence[int] | None = None) -> None:
        super().__init__()
        model = onnx.load(str(path))
        self.template = model
        weights = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
        self.input_name = model.graph.input[0].name
        self._nodes: list[onnx.NodeProto] = []
        self.convs = nn.ModuleDict()
        self.conv_of: dict[str, str] = {}  # node output -> module key
        self.consts = {k: v for k, v in weights.items() if v.ndim <= 1}
        self.heads = self._find_heads(model.graph)
        n_cls = weights["head.cls_preds.0.weight"].shape[0]
        self.class_rows = list(range(n_cls)) if class_rows is None else [int(r) for r in class_rows]
        bad = [r for r in self.class_rows if not 0 <= r < n_cls]
        if bad or not self.class_rows:
            raise ValueError(f"class_rows={list(class_rows or [])}: rows must be in 0..{n_cls - 1} (the model has "
                             f"{n_cls} classes) and at least one")
        for node in model.graph.node:
            if node.op_type == "Conv":
                key = f"c{len(self.convs)}"
                conv = _conv_from_node(node, weights)
                if node.input[1].startswith("head.cls_preds."):
                    conv = self._slice_rows(conv, self.class_rows)
                self.convs[key] = conv
                self.conv_of[node.output[0]] = key
            elif node.op_type not in ("Sigmoid", "Mul", "Add", "Concat", "Slice", "MaxPool", "Resize", "Reshape",
                                      "Transpose"):
                raise ValueError(f"{path}: operator {node.op_type} ({node.output[0]}) is not supported")
            self._nodes.append(node)
        self.n_classes = len(self.class_rows)
        self._body = self._body_nodes()

    def _body_nodes(self) -> list[onnx.NodeProto]:
        """The nodes up to the head convolutions: not the head's sigmoids (the losses take logits), its Concats,
        nor anything after them (Reshape, the anchors' Concat, Transpose)."""
        head_out = {v for h in self.heads for v in (h.obj, h.cls)}
        skipped = {h.concat for h in self.heads}
        body = []
        for node in self._nodes:
            if (node.output[0] in skipped or any(i in skipped for i in node.input)
                    or (node.op_type == "Sigmoid" and node.input[0] in head_out)):
                skipped.update(node.output)
                continue
            body.append(node)
        return body

    @staticmethod
    def _slice_rows(conv: nn.Conv2d, rows: list[int]) -> nn.Conv2d:
        new = nn.Conv2d(conv.in_channels, len(rows), conv.kernel_size, conv.stride, conv.padding, conv.dilation,
                        conv.groups, bias=conv.bias is not None)
        with torch.no_grad():
            new.weight.copy_(conv.weight[rows])
            if conv.bias is not None:
                new.bias.copy_(conv.bias[rows])
        return new

    @staticmethod
    def _find_heads(graph: onnx.GraphProto) -> list[HeadConvs]:
        """Per stride, the reg/obj/cls conv outputs and their Concat (the Reshape inputs, in output order)."""
        producer = {o: n for n in graph.node for o in n.output}
        heads = []
        for node in graph.node:
            if node.op_type != "Reshape":
                continue
            concat = producer[node.input[0]]
            parts = []
            for inp in concat.input:
                n = producer[inp]
                if n.op_type == "Sigmoid":
                    n = producer[n.input[0]]
                if n.op_type != "Conv":
                    raise ValueError(f"head concat {concat.output[0]}: input {inp} is not a (sigmoid of a) Conv")
                parts.append(n.output[0])
            if len(parts) != 3:
                raise ValueError(f"head concat {concat.output[0]} has {len(parts)} inputs, expected reg, obj, cls")
            heads.append(HeadConvs(reg=parts[0], obj=parts[1], cls=parts[2], concat=concat.output[0]))
        if len(heads) != len(STRIDES):
            raise ValueError(f"found {len(heads)} YOLOX head outputs, expected {len(STRIDES)}")
        return heads

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Run the graph up to each stride's head; see the class docstring for shapes."""
        env: dict[str, torch.Tensor] = {self.input_name: x}
        for node in self._body:
            env[node.output[0]] = self._run(node, env)
        return [torch.cat([env[h.reg], env[h.obj], env[h.cls]], dim=1) for h in self.heads]

    def _run(self, node: onnx.NodeProto, env: dict[str, torch.Tensor]) -> torch.Tensor:
        op, ins = node.op_type, node.input
        if op == "Conv":
            return self.convs[self.conv_of[node.output[0]]](env[ins[0]])
        if op == "Sigmoid":
            return torch.sigmoid(env[ins[0]])
        if op == "Mul":
            return env[ins[0]] * env[ins[1]]
        if op == "Add":
            return env[ins[0]] + env[ins[1]]
        if op == "Concat":
            return torch.cat([env[i] for i in ins], dim=int(_attrs(node)["axis"]))
        if op == "MaxPool":
            a = _attrs(node)
            return F.max_pool2d(env[ins[0]], a["kernel_shape"], a.get("strides", 1), a["pads"][:2])
        if op == "Resize":
            scale = self.consts[ins[2]]
            return F.interpolate(env[ins[0]], scale_factor=(float(scale[2]), float(scale[3])), mode="nearest")
        if op == "Slice":
            return self._slice(node, env)
        raise ValueError(f"operator {op} is not supported here")

    def _slice(self, node: onnx.NodeProto, env: dict[str, torch.Tensor]) -> torch.Tensor:
        x = env[node.input[0]]
        starts, ends, axes, steps = (self.consts[n].tolist() for n in node.input[1:5])
        idx = [slice(None)] * x.dim()
        for s, e, a, st in zip(starts, ends, axes, steps):
            idx[a] = slice(s, min(e, x.shape[a]), st)
        return x[tuple(idx)]

    def inference(self, x: torch.Tensor) -> torch.Tensor:
        """What the exported graph outputs: ``(B, A, 5 + nc)`` with box raw and objectness/classes after sigmoid."""
        outs = []
        for o in self.forward(x):
            o = torch.cat([o[:, :4], torch.sigmoid(o[:, 4:])], dim=1)
            outs.append(o.flatten(2))
        return torch.cat(outs, dim=2).permute(0, 2, 1)


def write_onnx(module: OnnxYolox, path: str | os.PathLike, class_names: Sequence[str],
               metadata: dict[str, str] | None = None) -> None:
    """Write ``module``'s weights into a copy of its graph at ``path``: class convolutions resized to
    ``len(class_names)`` outputs, the three Reshapes to ``(B, 5 + nc, -1)`` (batch copied from the input), the input
    ``(batch, 3, height, width)`` and output ``(batch, anchors, 5 + nc)`` dynamic, ``names`` in the metadata as
    Ultralytics writes it (``str`` of ``{index: name}``, read by :func:`aerodaas.perception.model_meta.metadata_names`)
    and ``head`` = ``yolox`` (how :func:`aerodaas.perception.decoders.inspect_model` tells it from an Ultralytics
    export), plus ``metadata``. Raises ValueError when the names do not match the module's class count."""
    if len(class_names) != module.n_classes:
        raise ValueError(f"class_names has {len(class_names)} names, the model has {module.n_classes} classes")
    model = copy.deepcopy(module.template)
    g = model.graph
    nc = module.n_classes
    new_init = {}
    for node in g.node:
        if node.op_type == "Conv":
            conv = module.convs[module.conv_of[node.output[0]]]
            new_init[node.input[1]] = conv.weight.detach().cpu().numpy().astype(np.float32)
            if conv.bias is not None:
                new_init[node.input[2]] = conv.bias.detach().cpu().numpy().astype(np.float32)
        elif node.op_type == "Reshape":
            new_init[node.input[1]] = np.array([0, 5 + nc, -1], dtype=np.int64)
    for i, init in enumerate(g.initializer):
        if init.name in new_init:
            g.initializer[i].CopyFrom(numpy_helper.from_array(new_init[init.name], init.name))
    for vi, dims in ((g.input[0], ("batch", 3, "height", "width")), (g.output[0], ("batch", "anchors", 5 + nc))):
        shape = vi.type.tensor_type.shape
        for d, v in zip(shape.dim, dims):
            d.Clear()
            if isinstance(v, str):
                d.dim_param = v
            else:
                d.dim_value = v
    del g.value_info[:]
    meta = {"names": str({i: n for i, n in enumerate(class_names)}), "head": "yolox", **(metadata or {})}
    del model.metadata_props[:]
    for k, v in meta.items():
        model.metadata_props.append(onnx.StringStringEntryProto(key=k, value=str(v)))
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
