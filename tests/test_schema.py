"""One schema: the plant parameter names, the MPC settings and the simulation come from the
core's single definitions; the stubs and the Python API are checked against them."""

import ast
from pathlib import Path

import riprs
from riprs.config import PARAMETERS

STUB = Path(riprs.__file__).with_name("_riprs.pyi")


def _stub():
    return ast.parse(STUB.read_text())


def _literal(tree, name):
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == name:
            sub = node.value
            assert isinstance(sub, ast.Subscript) and sub.value.id == "Literal"
            elts = sub.slice.elts if isinstance(sub.slice, ast.Tuple) else [sub.slice]
            return [e.value for e in elts]
    raise AssertionError(f"{name} not in the stub")


def _properties(tree, cls):
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            return [
                f.name
                for f in node.body
                if isinstance(f, ast.FunctionDef)
                and any(getattr(d, "id", None) == "property" for d in f.decorator_list)
            ]
    raise AssertionError(f"{cls} not in the stub")


def test_the_stub_parameter_names_are_the_core_table():
    # PARAMETERS is the core's Param table ([plant] keys); the stub's Literal must list
    # exactly those, in the same order.
    assert _literal(_stub(), "_ParameterName") == list(PARAMETERS)
    assert len(PARAMETERS) == 14


def test_furuta_params_properties_are_the_core_fields():
    fields = list(riprs.FurutaParams.qube_servo2().to_dict())
    props = _properties(_stub(), "FurutaParams")
    assert props == fields
    # Every [plant] key is a field; the only other field is the gravitational acceleration.
    assert set(fields) - set(PARAMETERS) == {"g"}
    p = riprs.FurutaParams.qube_servo2()
    for name in fields:
        assert getattr(p, name) == p.to_dict()[name]
        changed = p.replace(**{name: 2.0 * getattr(p, name)})
        assert getattr(changed, name) == 2.0 * getattr(p, name)


def test_every_plant_key_reaches_the_plant_and_a_bad_one_is_named(tmp_path):
    base = riprs.Spec().plant.params.to_dict()
    for name in PARAMETERS:
        value = base[name] * 1.5 if base[name] else 1e-3
        f = tmp_path / f"{name}.toml"
        f.write_text(f"[plant]\n{name} = {value!r}\n")
        spec = riprs.load_config(f)
        got = spec.plant.params.to_dict()
        assert got[name] == value, name
        assert all(got[k] == base[k] for k in base if k != name), name
        f.write_text(f"[plant]\n{name} = -1.0\n")
        try:
            riprs.load_config(f)
        except riprs.ConfigError as e:
            assert f"plant.{name}" in str(e)
        else:
            raise AssertionError(f"plant.{name} = -1 accepted")
