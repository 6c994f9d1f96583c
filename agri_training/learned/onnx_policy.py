"""ONNX policies, run through the CPU-independent float64 path: a graph interpreter over :mod:`.inference`.

The contract of an ONNX policy file: one graph input, the observation flattened by
``gymnasium.spaces.flatten`` (float32, batch first); its first output, the action (clipped to the action space
here; for a ``Discrete`` action space, one score per action, of which the highest is taken). An optional
sidecar (:mod:`.sidecar`) may name the observation normalisation and the env arguments.

The ``onnx`` package parses the file; no runtime decides a bit. :class:`OnnxGraph` evaluates the graph's nodes
in float64 with the rules of :mod:`agri_training.learned.inference`: matrix products are the element-wise
products folded in :func:`~.inference.fold_sum`'s order (Gemm with a bias through the compiled
:func:`~.inference.dense_layer`, the same bits), ``tanh``, ``exp`` (Sigmoid, Elu) from its own correctly rounded
operations, and otherwise only numpy's element-wise ``+ - * /``, ``maximum``, ``minimum`` and ``where``. An MLP
exported by ``torch.onnx.export`` therefore acts within float32 rounding of the torch network, and the same on
every x86-64 CPU, so its leaderboard entries verify bit for bit.

Only the operators of MLPs are run (:data:`SUPPORTED_OPS`); any other, an operator of a custom domain, a local
function, a subgraph or external tensor data is refused with a ``ValueError`` naming it. Nothing in the file is
executed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import agri_envs
from agri_training.core.filecache import FileCache
from agri_training.learned.inference import dense_layer, exp, fold_sum, tanh
from agri_training.learned.policy import ObsNormalization
from agri_training.learned.sidecar import read_sidecar, sidecar_path

#: The operators an ONNX policy may use (those of MLPs as ``torch.onnx.export`` writes them).
SUPPORTED_OPS = (
    "MatMul", "Gemm", "Add", "Sub", "Mul", "Div", "Relu", "Tanh", "Sigmoid", "Elu", "LeakyRelu", "Clip",
    "Concat", "Identity", "Flatten", "Reshape", "Constant", "Squeeze", "Unsqueeze",
)  # fmt: skip
#: The operator domains accepted (the default ONNX domain only: no custom operators).
_DOMAINS = ("", "ai.onnx")


def _onnx() -> Any:
    try:
        import onnx
    except ImportError as exc:
        raise ValueError("ONNX policies need the onnx package: pip install -e '.[train]'") from exc
    return onnx


@dataclasses.dataclass(frozen=True)
class OnnxNode:
    """One node of a graph: its operator, input and output names, attributes (plain values and arrays)."""

    op: str
    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    attributes: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class OnnxGraph:
    """A parsed ONNX graph of supported operators, evaluated in float64 (the module docstring).

    Attributes:
        input_name: The graph's one input (the flattened observation).
        input_width: Its declared last dimension, or None when it is not fixed.
        output_name: The graph's first output (the action).
        nodes: The nodes in the file's (topological) order.
        constants: Initializers by name: float tensors as float64, integer tensors as int64.
        opset: The default domain's opset version.
    """

    input_name: str
    input_width: int | None
    output_name: str
    nodes: tuple[OnnxNode, ...]
    constants: Mapping[str, np.ndarray]
    opset: int

    @classmethod
    def parse(cls, data: bytes, where: str = "the ONNX file") -> OnnxGraph:
        """Parse and check a serialized ONNX model.

        Raises:
            ValueError: For a file that does not parse, an unsupported operator (named), a custom domain, a
                local function, external data, or a graph without exactly one input.
        """
        onnx = _onnx()
        try:
            model = onnx.load_model_from_string(data)
        except Exception as exc:  # protobuf's DecodeError and friends: not an ONNX file
            raise ValueError(f"{where} is not an ONNX model: {type(exc).__name__}: {exc}") from None
        graph = model.graph
        if len(model.functions):
            raise ValueError(f"{where} defines local functions ({model.functions[0].name!r}); only plain graphs run")
        opset = 0
        for imp in model.opset_import:
            if imp.domain not in _DOMAINS:
                raise ValueError(f"{where} imports the custom operator domain {imp.domain!r}; only ONNX's own run")
            opset = int(imp.version)
        if len(graph.sparse_initializer):
            raise ValueError(f"{where} has sparse initializers, which are not supported")
        constants: dict[str, np.ndarray] = {}
        for tensor in graph.initializer:
            if tensor.data_location == onnx.TensorProto.EXTERNAL:
                raise ValueError(
                    f"{where}: tensor {tensor.name!r} is stored outside the file (its sha256 would not pin the "
                    "weights): export one file, torch.onnx.export(..., external_data=False)"
                )
            constants[tensor.name] = _array(onnx, tensor)
        nodes = []
        for k, node in enumerate(graph.node):
            name = node.name or f"#{k}"
            if node.domain not in _DOMAINS:
                raise ValueError(f"{where}: node {name} uses the custom operator {node.domain}.{node.op_type}")
            if node.op_type not in SUPPORTED_OPS:
                raise ValueError(
                    f"{where}: ONNX operator {node.op_type!r} (node {name}) is not supported; supported: "
                    f"{', '.join(SUPPORTED_OPS)}"
                )
            attributes = {a.name: _attribute(onnx, a, where, name) for a in node.attribute}
            nodes.append(OnnxNode(node.op_type, name, tuple(node.input), tuple(node.output), attributes))
        inputs = [i for i in graph.input if i.name not in constants]
        if len(inputs) != 1 or not len(graph.output):
            raise ValueError(
                f"{where} must have one input (the flattened observation) and an output (the action), has "
                f"{len(inputs)} input(s) and {len(graph.output)} output(s)"
            )
        dims = inputs[0].type.tensor_type.shape.dim
        width = int(dims[-1].dim_value) if len(dims) and dims[-1].HasField("dim_value") else None
        return cls(inputs[0].name, width, graph.output[0].name, tuple(nodes), constants, opset)

    def run(self, x: np.ndarray) -> np.ndarray:
        """The graph's output for a ``(batch, n)`` float64 input.

        Raises:
            ValueError: When a node cannot take the shapes it is given (the message names the node).
        """
        values: dict[str, np.ndarray] = dict(self.constants)
        values[self.input_name] = np.asarray(x, dtype=np.float64)
        for node in self.nodes:
            args = [values[i] if i else None for i in node.inputs]
            try:
                outs = _OPS[node.op](self, node, args)
            except (ValueError, IndexError, KeyError) as exc:
                raise ValueError(f"ONNX node {node.name} ({node.op}) failed: {exc}") from None
            for name, value in zip(node.outputs, outs, strict=False):
                values[name] = value
        return values[self.output_name]


def _array(onnx: Any, tensor: Any) -> np.ndarray:
    """A TensorProto as an array: floats as float64 (exact from float32), integers as int64."""
    value = onnx.numpy_helper.to_array(tensor)
    if np.issubdtype(value.dtype, np.floating):
        return np.asarray(value, dtype=np.float64)
    if np.issubdtype(value.dtype, np.integer) or value.dtype == np.bool_:
        return np.asarray(value, dtype=np.int64)
    raise ValueError(f"tensor {tensor.name!r} has the unsupported type {value.dtype}")


def _attribute(onnx: Any, attribute: Any, where: str, node: str) -> Any:
    kind = attribute.type
    types = onnx.AttributeProto
    if kind in (types.GRAPH, types.GRAPHS):
        raise ValueError(f"{where}: node {node} holds a subgraph, which is not supported")
    if kind == types.TENSOR:
        return _array(onnx, attribute.t)
    value = onnx.helper.get_attribute_value(attribute)
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, (list, tuple)):
        return tuple(value)
    return value


# ---- the operators: each takes (graph, node, inputs) and returns its outputs ----------------------------------

Op = Callable[[OnnxGraph, OnnxNode, list[Any]], list[np.ndarray]]


def _fold_product(a: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``a @ weight.T`` for ``(batch, k)`` and ``(n, k)``, summed in :func:`fold_sum`'s order."""
    if a.ndim != 2 or weight.ndim != 2:
        raise ValueError(f"matrix products of 2-D operands only (an MLP), got shapes {a.shape} and {weight.shape}")
    if a.shape[1] != weight.shape[1]:
        raise ValueError(f"{a.shape[1]} input values, the weights expect {weight.shape[1]}")
    return fold_sum(a[:, None, :] * weight[None, :, :])


def _matmul(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    a, b = args
    if b.ndim != 2:
        raise ValueError(f"MatMul with a {b.ndim}-D right operand is not supported (an MLP's weights are 2-D)")
    return [_fold_product(a, b.T)]


def _gemm(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    a, b = args[0], args[1]
    c = args[2] if len(args) > 2 else None
    at = node.attributes
    a = a.T if at.get("transA", 0) else a
    weight = b if at.get("transB", 0) else b.T  # (n_out, n_in)
    alpha, beta = float(at.get("alpha", 1.0)), float(at.get("beta", 1.0))
    if alpha == 1.0 and beta == 1.0 and c is not None and c.ndim == 1 and c.shape[0] == weight.shape[0]:
        if a.ndim != 2 or a.shape[1] != weight.shape[1]:
            raise ValueError(f"{a.shape[-1]} input values, the weights expect {weight.shape[1]}")
        # the compiled layer: the products folded in fold_sum's order, plus the bias (the same bits)
        return [dense_layer(np.ascontiguousarray(a), np.ascontiguousarray(weight), np.ascontiguousarray(c), 0)]
    y = _fold_product(a, weight)
    if alpha != 1.0:
        y = alpha * y
    if c is not None:
        y = y + (c if beta == 1.0 else beta * c)
    return [y]


def _binary(function: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Op:
    def op(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
        return [function(args[0], args[1])]

    return op


def _divide(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if np.issubdtype(a.dtype, np.integer) and np.issubdtype(b.dtype, np.integer):
        return np.asarray(np.trunc(a / b), dtype=np.int64)  # ONNX's integer division truncates
    return np.asarray(a / b, dtype=np.float64)


def _unary(function: Callable[[np.ndarray, Mapping[str, Any]], np.ndarray]) -> Op:
    def op(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
        return [function(np.asarray(args[0], dtype=np.float64), node.attributes)]

    return op


def _sigmoid(x: np.ndarray, at: Mapping[str, Any]) -> np.ndarray:
    return 1.0 / (1.0 + exp(-x))


def _elu(x: np.ndarray, at: Mapping[str, Any]) -> np.ndarray:
    alpha = float(at.get("alpha", 1.0))
    negative = exp(np.minimum(x, 0.0)) - 1.0
    return np.where(x > 0, x, negative if alpha == 1.0 else alpha * negative)


def _leaky_relu(x: np.ndarray, at: Mapping[str, Any]) -> np.ndarray:
    return np.where(x >= 0, x, float(at.get("alpha", 0.01)) * x)


def _clip(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    x = np.asarray(args[0], dtype=np.float64)
    if g.opset < 11:
        low, high = node.attributes.get("min"), node.attributes.get("max")
    else:
        low = args[1] if len(args) > 1 else None
        high = args[2] if len(args) > 2 else None
    if low is not None:
        x = np.maximum(x, np.asarray(low, dtype=np.float64))
    if high is not None:
        x = np.minimum(x, np.asarray(high, dtype=np.float64))
    return [x]


def _constant(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    at = node.attributes
    if "value" in at:
        return [at["value"]]
    for key, dtype in (("value_float", np.float64), ("value_floats", np.float64), ("value_int", np.int64),
                       ("value_ints", np.int64)):  # fmt: skip
        if key in at:
            return [np.asarray(at[key], dtype=dtype)]
    raise ValueError(f"Constant with attributes {sorted(at)} is not supported")


def _concat(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    parts = [a for a in args if a is not None]
    return [np.concatenate(parts, axis=int(node.attributes.get("axis", 0)))]


def _flatten(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    x = args[0]
    axis = int(node.attributes.get("axis", 1)) % (x.ndim + 1) if x.ndim else 0
    outer = int(np.prod(x.shape[:axis])) if axis else 1
    return [x.reshape(outer, -1)]


def _reshape(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    x, shape = args[0], [int(s) for s in np.asarray(args[1]).ravel()]
    if not node.attributes.get("allowzero", 0):
        shape = [x.shape[i] if s == 0 else s for i, s in enumerate(shape)]
    return [x.reshape(shape)]


def _axes(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[int] | None:
    if len(args) > 1 and args[1] is not None:
        return [int(a) for a in np.asarray(args[1]).ravel()]
    axes = node.attributes.get("axes")
    return None if axes is None else [int(a) for a in axes]


def _squeeze(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    axes = _axes(g, node, args)
    x = args[0]
    return [np.squeeze(x) if axes is None else np.squeeze(x, axis=tuple(a % x.ndim for a in axes))]


def _unsqueeze(g: OnnxGraph, node: OnnxNode, args: list[Any]) -> list[np.ndarray]:
    axes = _axes(g, node, args)
    if axes is None:
        raise ValueError("Unsqueeze needs axes")
    x = args[0]
    rank = x.ndim + len(axes)
    for a in sorted(a % rank for a in axes):
        x = np.expand_dims(x, a)
    return [x]


_OPS: dict[str, Op] = {
    "MatMul": _matmul,
    "Gemm": _gemm,
    "Add": _binary(np.add),
    "Sub": _binary(np.subtract),
    "Mul": _binary(np.multiply),
    "Div": _binary(_divide),
    "Relu": _unary(lambda x, at: np.maximum(x, 0.0)),
    "Tanh": _unary(lambda x, at: tanh(x)),
    "Sigmoid": _unary(_sigmoid),
    "Elu": _unary(_elu),
    "LeakyRelu": _unary(_leaky_relu),
    "Clip": _clip,
    "Concat": _concat,
    "Identity": lambda g, node, args: [args[0]],
    "Flatten": _flatten,
    "Reshape": _reshape,
    "Constant": _constant,
    "Squeeze": _squeeze,
    "Unsqueeze": _unsqueeze,
}
assert set(_OPS) == set(SUPPORTED_OPS)

#: Graphs read in this process (a fresh policy per episode shares the parsed graph).
_GRAPHS: FileCache[OnnxGraph] = FileCache()


def load_graph(path: Path) -> OnnxGraph:
    """The parsed graph of an ONNX file, read once per process while the file is unchanged.

    Raises:
        ValueError: See :meth:`OnnxGraph.parse`.
    """
    return _GRAPHS.get([path], None, lambda: OnnxGraph.parse(path.read_bytes(), str(path)))


def check_onnx_file(path: Path) -> None:
    """Parse and check an ONNX policy file and its sidecar without an env (see :meth:`OnnxGraph.parse`)."""
    load_graph(path)
    read_sidecar(path)


def flatten_observations(space: gym.Space[Any], observation: Any) -> tuple[np.ndarray, bool]:
    """``(batch, flatdim)`` float32 rows of ``gymnasium.spaces.flatten`` and whether the input was a batch."""
    first = observation
    shape: tuple[int, ...] | None = getattr(space, "shape", None)
    if isinstance(space, gym.spaces.Dict):
        key = next(iter(space.spaces))
        first, shape = observation[key], space.spaces[key].shape
    batch = shape is not None and np.ndim(first) > len(shape)
    if not batch:
        return np.asarray(gym.spaces.flatten(space, observation), dtype=np.float32)[None, :], False
    n = len(first)
    if isinstance(space, gym.spaces.Dict):
        rows = [gym.spaces.flatten(space, {k: v[i] for k, v in observation.items()}) for i in range(n)]
    else:
        rows = [gym.spaces.flatten(space, observation[i]) for i in range(n)]
    return np.asarray(rows, dtype=np.float32), True


#: Graphs with their sidecar's normalisation, checked against the spaces they drive (see :func:`_checked`).
_CHECKED: FileCache[tuple[OnnxGraph, ObsNormalization | None]] = FileCache()


def _checked(
    path: Path, observation_space: gym.Space[Any], action_space: gym.Space[Any], env_name: str
) -> tuple[OnnxGraph, ObsNormalization | None]:
    """The graph of ``path`` and its sidecar's normalisation, checked against the spaces once per process.

    The evaluator builds a fresh policy for every episode (and every sub-env of a batch); reading the sidecar
    and running the graph once on zeros took about 5 ms each time. Both are immutable and shared while the
    file and its sidecar are unchanged, as a run's network is (:class:`~agri_training.core.filecache.FileCache`).

    Raises:
        ValueError: When the graph does not take the env's flattened observation (both widths named), its
            output is not the action's size, or the file or its sidecar is refused.
    """

    def make() -> tuple[OnnxGraph, ObsNormalization | None]:
        graph = load_graph(path)
        normalization = read_sidecar(path).normalization
        width = int(gym.spaces.flatdim(observation_space))
        if graph.input_width is not None and graph.input_width != width:
            raise ValueError(
                f"{path}: the graph's input has {graph.input_width} values, {env_name}'s flattened "
                f"observation has {width}: the policy was made for another env or other env arguments"
            )
        normalized = normalization.mean[""].size if normalization is not None else width
        if normalized != width:
            raise ValueError(
                f"{path}: the sidecar normalises {normalized} values, {env_name}'s flattened "
                f"observation has {width}"
            )
        try:
            out = graph.run(np.zeros((1, width)))
        except ValueError as exc:
            raise ValueError(
                f"{path}: the graph does not take {env_name}'s flattened observation ({width} values): {exc}"
            ) from None
        want = _action_size(action_space)
        if out.size != want:
            raise ValueError(f"{path}: the graph outputs {out.size} values, {env_name}'s action needs {want}")
        return graph, normalization

    return _CHECKED.get([path, sidecar_path(path)], (repr(observation_space), repr(action_space)), make)


def _action_size(action_space: gym.Space[Any]) -> int:
    """How many values an action holds (a Discrete action: one per choice, as a policy's output)."""
    if isinstance(action_space, gym.spaces.Discrete):
        return int(action_space.n)
    return int(np.prod(action_space.shape or ()))


class OnnxPolicy:
    """An ONNX policy file acting on an env's raw observations: SB3's ``predict``, deterministic.

    Args:
        path: The ``.onnx`` file (its sidecar, if any, beside it: :mod:`.sidecar`).
        env: The env it drives (its spaces).

    Raises:
        ValueError: When the graph does not take the env's flattened observation (both widths named), its
            output is not the action's size, or the file or its sidecar is refused.
    """

    #: Its actions are the same bits on every x86-64 CPU.
    cpu_independent = True

    def __init__(self, path: Path, env: Any) -> None:
        self.path = Path(path)
        if agri_envs.is_parallel_env(env):
            raise ValueError(f"{self.path}: ONNX policies drive single-agent envs, not the PettingZoo env {env}")
        if not isinstance(env.action_space, (gym.spaces.Box, gym.spaces.Discrete)):
            raise ValueError(f"{self.path}: ONNX policies drive Box or Discrete action spaces, got {env.action_space}")
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        env_name = getattr(getattr(env, "spec", None), "id", None) or type(getattr(env, "unwrapped", env)).__name__
        self.graph, self.normalization = _checked(self.path, self.observation_space, self.action_space, env_name)

    def act(self, observation: Any) -> tuple[np.ndarray, bool]:
        """The actions for one observation or a batch, and whether it was a batch."""
        flat, batch = flatten_observations(self.observation_space, observation)
        if self.normalization is not None:
            flat = self.normalization.normalize(flat)
        y = self.graph.run(flat.astype(np.float64))
        n = flat.shape[0]
        if isinstance(self.action_space, gym.spaces.Discrete):
            return np.argmax(y.reshape(n, -1), axis=1), batch
        box = self.action_space
        shape = (n, *box.shape)
        low = np.asarray(box.low, dtype=np.float64)
        high = np.asarray(box.high, dtype=np.float64)
        action = np.minimum(np.maximum(y.reshape(shape), low), high)
        return action.astype(box.dtype if box.dtype is not None else np.float32), batch

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Sequence[bool] | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's ``predict``: the graph's action for an observation (or a batch), clipped to the action space."""
        actions, batch = self.act(observation)
        return (actions if batch else actions[0]), state
