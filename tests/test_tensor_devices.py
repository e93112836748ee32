"""Every tensor factory call in `rllib_asor/` says where its tensor lives.

A tensor made without a device lands on the CPU; on a GPU Learner it then meets cuda tensors
and the first `torch.cat` or arithmetic fails. CI has no GPU, so this test reads the source
instead: each `torch.<factory>(...)` call must

- pass `device=...`, or
- be followed at once by `.to(<device or tensor>)` (possibly after dtype/shape methods such
  as `.float()`), which is how a `from_numpy` / `as_tensor` bridge reaches the device, or
- copy another tensor's device: the `*_like` factories, or
- be module state: the value of `nn.Parameter(...)` or of `self.register_buffer(name, ...)`,
  which moves with `module.to(device)` (RLlib moves every module to the Learner's device), or
- be listed in `ALLOWED` below with a one-line reason (keyed by file, enclosing function and
  factory, so the list survives edits; an entry that matches nothing fails the test).

The way back fails the same way: `.numpy()` of a cuda tensor raises, so every `.numpy()` must
come after `.cpu()` (dtype and `detach` calls may sit between them).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rllib_asor"

FACTORIES = frozenset(
    {
        "zeros", "ones", "full", "empty", "arange", "tensor", "as_tensor", "from_numpy",
        "asarray", "randn", "rand", "randint", "randperm", "linspace", "logspace", "eye",
        "normal", "empty_strided", "scalar_tensor",
    }
)
LIKE = frozenset(
    {"zeros_like", "ones_like", "full_like", "empty_like", "randn_like", "rand_like",
     "randint_like"}
)
# Methods that may sit between the factory and its `.to(...)` (they keep the device).
PASS_THROUGH = frozenset(
    {"float", "double", "long", "int", "bool", "half", "contiguous", "reshape", "view",
     "unsqueeze", "squeeze", "flatten", "clone", "detach", "t"}
)
DTYPES = frozenset(
    {"float", "float16", "float32", "float64", "double", "half", "bfloat16", "long", "int",
     "int8", "int16", "int32", "int64", "uint8", "bool", "complex64"}
)

# (file relative to rllib_asor/, enclosing function's qualified name, factory): reason.
ALLOWED: dict[tuple[str, str, str], str] = {
    ("asor/archive.py", "discounted_return_to_go", "from_numpy"):
        "CPU numpy bridge for scipy's lfilter; the caller moves it with .to(archive buffer)",
    ("algorithms/common/learner_speed.py", "IndexSelectShuffleBatch.shuffle", "from_numpy"):
        "one CPU permutation for numpy and torch columns; take_rows moves it per column",
    ("algorithms/common/inverse_dynamics.py", "InverseDynamicsModel.__init__", "zeros"):
        "the action bounds as buffers at construction; module.to(device) moves them",
    ("algorithms/common/inverse_dynamics.py", "InverseDynamicsModel.__init__", "as_tensor"):
        "the action bounds as buffers at construction; module.to(device) moves them",
    ("asor/trainer.py", "_to_tensors", "from_numpy"):
        "optimiser moments restored from numpy; Optimizer.load_state_dict moves them to the params",
}


@dataclass(frozen=True)
class Call:
    path: str
    line: int
    function: str
    factory: str

    @property
    def key(self) -> tuple[str, str, str]:
        return (self.path, self.function, self.factory)

    def __str__(self) -> str:
        return f"rllib_asor/{self.path}:{self.line} torch.{self.factory}(...) in {self.function}"


def _is_torch_call(node: ast.AST, names: frozenset[str]) -> str | None:
    """The factory name when `node` is `torch.<name>(...)`."""
    if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Attribute):
        return None
    func = node.func
    if func.attr in names and isinstance(func.value, ast.Name) and func.value.id == "torch":
        return func.attr
    return None


def _names_device(arg: ast.expr) -> bool:
    """False for `.to(torch.float32)`-like arguments (a dtype is not a device)."""
    return not (
        isinstance(arg, ast.Attribute)
        and isinstance(arg.value, ast.Name)
        and arg.value.id == "torch"
        and arg.attr in DTYPES
    )


def _moved_to_device(node: ast.Call, parents: dict[ast.AST, ast.AST]) -> bool:
    """`torch.f(...)[.float()...].to(<device>)`."""
    current: ast.AST = node
    while True:
        attr = parents.get(current)
        call = parents.get(attr) if attr is not None else None
        if not (isinstance(attr, ast.Attribute) and isinstance(call, ast.Call) and call.func is attr):
            return False
        if attr.attr == "to":
            if any(k.arg == "device" for k in call.keywords):
                return True
            return bool(call.args) and _names_device(call.args[0])
        if attr.attr not in PASS_THROUGH:
            return False
        current = call


def _is_module_state(node: ast.Call, parents: dict[ast.AST, ast.AST]) -> bool:
    """The value of `nn.Parameter(...)` or `<obj>.register_buffer(name, ...)`, possibly through
    an in-place initialiser (`torch.empty(...).uniform_(a, b)`)."""
    while True:  # climb `<node>.uniform_(...)`-style calls
        attr = parents.get(node)
        call = parents.get(attr) if attr is not None else None
        if not (isinstance(attr, ast.Attribute) and attr.attr.endswith("_")
                and isinstance(call, ast.Call) and call.func is attr):
            break
        node = call
    parent = parents.get(node)
    if not isinstance(parent, ast.Call) or not isinstance(parent.func, ast.Attribute | ast.Name):
        return False
    name = parent.func.attr if isinstance(parent.func, ast.Attribute) else parent.func.id
    if name == "Parameter":
        return node in parent.args
    return name == "register_buffer" and len(parent.args) >= 2 and parent.args[1] is node


def _functions(tree: ast.Module) -> dict[ast.AST, str]:
    """Each node → the qualified name of the function (or class) it sits in."""
    owner: dict[ast.AST, str] = {}

    def visit(node: ast.AST, scope: str) -> None:
        for child in ast.iter_child_nodes(node):
            inner = scope
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                inner = f"{scope}.{child.name}" if scope != "<module>" else child.name
            owner[child] = inner
            visit(child, inner)

    visit(tree, "<module>")
    return owner


def factory_calls(source: str, path: str) -> tuple[list[Call], list[Call]]:
    """(calls that name their device, calls that do not) in one file's source."""
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    owner = _functions(tree)
    good: list[Call] = []
    bad: list[Call] = []
    for node in ast.walk(tree):
        if _is_torch_call(node, LIKE):
            continue
        factory = _is_torch_call(node, FACTORIES)
        if factory is None:
            continue
        assert isinstance(node, ast.Call)
        call = Call(path, node.lineno, owner.get(node, "<module>"), factory)
        ok = (
            any(k.arg == "device" for k in node.keywords)
            or _moved_to_device(node, parents)
            or _is_module_state(node, parents)
        )
        (good if ok else bad).append(call)
    return good, bad


def _scan() -> tuple[list[Call], list[Call]]:
    good: list[Call] = []
    bad: list[Call] = []
    for file in sorted(PACKAGE.rglob("*.py")):
        path = file.relative_to(PACKAGE).as_posix()
        g, b = factory_calls(file.read_text(), path)
        good += g
        bad += b
    return good, sorted(bad, key=lambda c: (c.path, c.line))


def test_every_tensor_factory_names_its_device() -> None:
    _, bad = _scan()
    unlisted = [c for c in bad if c.key not in ALLOWED]
    assert not unlisted, (
        "tensor factory calls without a device (pass device=..., follow with .to(device), "
        "or add to ALLOWED in tests/test_tensor_devices.py with a reason):\n"
        + "\n".join(f"  {c}" for c in unlisted)
    )


def numpy_calls_off_the_cpu(source: str, path: str) -> list[str]:
    """`<tensor>.numpy()` calls not preceded by `.cpu()` in one file's source."""
    tree = ast.parse(source)
    bad = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "numpy" and not node.args):
            continue
        receiver = node.func.value
        while (isinstance(receiver, ast.Call) and isinstance(receiver.func, ast.Attribute)
               and receiver.func.attr in PASS_THROUGH):
            receiver = receiver.func.value
        on_cpu = (isinstance(receiver, ast.Call) and isinstance(receiver.func, ast.Attribute)
                  and receiver.func.attr == "cpu")
        if not on_cpu:
            bad.append(f"rllib_asor/{path}:{node.lineno}")
    return bad


def test_every_numpy_conversion_comes_from_the_cpu() -> None:
    bad = []
    for file in sorted(PACKAGE.rglob("*.py")):
        bad += numpy_calls_off_the_cpu(file.read_text(), file.relative_to(PACKAGE).as_posix())
    assert not bad, "`.numpy()` without `.cpu()` first (fails on a cuda tensor):\n" + "\n".join(bad)
    snippet = "a = x.numpy()\nb = x.detach().cpu().double().numpy()\nc = x.cpu().numpy()\n"
    assert numpy_calls_off_the_cpu(snippet, "snippet.py") == ["rllib_asor/snippet.py:1"]


def test_allow_list_entries_are_used_and_explained() -> None:
    _, bad = _scan()
    used = {c.key for c in bad}
    stale = sorted(set(ALLOWED) - used)
    assert not stale, f"ALLOWED entries that match no device-less call any more: {stale}"
    assert all(len(reason.split()) >= 4 for reason in ALLOWED.values())


def test_the_checker_catches_a_missing_device() -> None:
    """The rules on small snippets: what passes and what is flagged."""
    source = '''
import torch
from torch import nn
def f(x, d):
    a = torch.full((3,), 1.0)                       # flagged
    b = torch.full((3,), 1.0, device=x.device)
    c = torch.from_numpy(x).float().to(d)
    e = torch.zeros(3).to(torch.float32)            # flagged: a dtype is no device
    g = torch.zeros_like(x)
    return torch.cat([a, b, c, e, g])
class M(nn.Module):
    def __init__(self):
        super().__init__()
        self.register_buffer("s", torch.zeros(3))
        self.w = nn.Parameter(torch.ones(2))
        self.bad = torch.arange(4)                   # flagged: a plain attribute
        self.u = nn.Parameter(torch.empty(2).uniform_(-1, 1))
        self.v = nn.Parameter(-5 * torch.ones(2))   # flagged: arithmetic is no initialiser
'''
    good, bad = factory_calls(source, "snippet.py")
    assert sorted((c.line, c.factory) for c in bad) == [
        (5, "full"), (8, "zeros"), (16, "arange"), (18, "ones")
    ]
    assert len(good) == 5
    assert {c.function for c in bad if c.line > 10} == {"M.__init__"}


def test_the_scan_sees_the_package() -> None:
    """Guards against a scan that silently finds nothing (wrong root, renamed package)."""
    good, bad = _scan()
    assert len(good) + len(bad) > 50
    assert any(c.path == "asor/archive.py" and c.function == "StateArchive._insert" for c in good)
