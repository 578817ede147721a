"""Reusable models of ``models/`` (package ``garage_mj.models``) as stamps for scene builders.

``dm_control.mjcf`` attach is the textbook way to reuse a model, but attaching a hundred parked
cars costs about a second (a deep copy and a namespace per car). A scene instead copies a model's
default classes and materials once, then stamps its body per placement: a body named after the
placement (``parkedcar_12``) holding the model's geoms. The semantic class still comes from the
body name (:mod:`garage_mj.scene.semantics`).

Speed: ``dm_control.mjcf`` costs about 60 us to create an element and as much again per array
attribute (``pos``, ``size``) it writes to XML. :func:`install` therefore turns every geom of the
model into a default class of its own (``<model>_geom_<geom>``, nested under the geom's class, so
inheritance is unchanged) holding the geom's type, size, pos, material, ...; a stamped geom is
then just ``name`` + ``class``. The compiled model is the same as with the attributes inline.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from dm_control import mjcf

PARKED_CAR = "parked_car"
PILLAR = "pillar"


def model_path(name: str) -> Path:
    """Path of ``models/<name>/<name>.xml`` inside the installed package."""
    path = Path(str(resources.files("garage_mj.models").joinpath(name, f"{name}.xml")))
    if not path.is_file():
        raise FileNotFoundError(f"model {name!r} not found at {path}; is garage_mj.models installed?")
    return path


@dataclass(frozen=True)
class Template:
    """One model: its defaults, materials and the geoms of its single top-level body."""

    name: str
    defaults: tuple[tuple[str, str | None, dict], ...]  # (class, parent class, geom attributes)
    materials: tuple[tuple[str, dict], ...]  # (name, attributes)
    childclass: str | None
    geoms: tuple[dict, ...]  # attributes per geom (class and material are template-local names)


def _ref(value) -> str | None:
    if value is None:
        return None
    return value if isinstance(value, str) else value.name if hasattr(value, "name") else value.dclass


@functools.cache
def load_template(name: str) -> Template:
    """Parse ``models/<name>/<name>.xml`` once (cached)."""
    root = mjcf.from_path(str(model_path(name)))
    defaults = []

    def walk(d, parent: str | None) -> None:
        for child in d.all_children():
            if child.tag == "default":
                defaults.append((child.dclass, parent, child.geom.get_attributes()))
                walk(child, child.dclass)

    walk(root.default, None)
    materials = tuple(
        (m.name, {k: v for k, v in m.get_attributes().items() if k != "name"}) for m in root.asset.material
    )
    bodies = root.worldbody.body
    if len(bodies) != 1:
        raise ValueError(f"model {name!r} must have exactly one top-level body, found {len(bodies)}")
    body = bodies[0]
    geoms = []
    for g in body.geom:
        attrs = g.get_attributes()
        attrs["dclass"] = _ref(attrs.get("dclass"))
        attrs["material"] = _ref(attrs.get("material"))
        geoms.append({k: v for k, v in attrs.items() if v is not None})
    return Template(name, tuple(defaults), materials, _ref(body.childclass), tuple(geoms))


def material_name(template: Template, local: str | None) -> str | None:
    return None if local is None else f"{template.name}_{local}"


def geom_class_name(template: Template, index: int) -> str:
    """Scene-wide default class holding all attributes of the template's ``index``-th geom."""
    gname = template.geoms[index].get("name") or str(index)
    return f"{template.name}_geom_{gname}"


def resolved_geom_attributes(template: Template, geom: dict) -> dict:
    """A template geom's attributes with its default classes applied (as MuJoCo would)."""
    parents = {dclass: (parent, attrs) for dclass, parent, attrs in template.defaults}
    chain = []
    local = geom.get("dclass") or template.childclass
    while local is not None:
        parent, attrs = parents[local]
        chain.append(attrs)
        local = parent
    out: dict = {}
    for attrs in reversed(chain):
        out.update(attrs)
    out.update((k, v) for k, v in geom.items() if k not in ("name", "dclass"))
    return out


def install(root: mjcf.RootElement, template: Template, *, z_scale: float = 1.0) -> None:
    """Add ``template``'s materials and one default class per geom to ``root`` (once per scene).

    A geom's class (:func:`geom_class_name`) holds all its attributes with the model's default
    classes already applied, so the scene needs no copy of those classes (each ``default``
    element costs ``dm_control`` about a millisecond). Heights (``size`` z and ``pos`` z) are
    scaled by ``z_scale`` (e.g. a pillar stretched to the ceiling).
    """
    for name, attrs in template.materials:
        root.asset.add("material", name=material_name(template, name), **attrs)
    for k, g in enumerate(template.geoms):
        attrs = resolved_geom_attributes(template, g)
        if "material" in attrs:
            attrs["material"] = material_name(template, attrs["material"])
        if z_scale != 1.0:
            if "size" in attrs and len(attrs["size"]) > 2:
                attrs["size"] = [*attrs["size"][:2], attrs["size"][2] * z_scale]
            if "pos" in attrs:
                attrs["pos"] = [*attrs["pos"][:2], attrs["pos"][2] * z_scale]
        root.default.add("default", dclass=geom_class_name(template, k)).geom.set_attributes(**attrs)


def stamp(parent, template: Template, name: str, pos, yaw: float):
    """Add one instance of ``template`` under ``parent`` as a body called ``name``; returns the body.

    Needs :func:`install` on the scene first. Angles are radians (the scene sets ``compiler
    angle="radian"``). Geoms are named ``<name>_<geom>`` so contacts and segmentation read as the
    instance's class (and because ``dm_control`` writes unnamed elements slowly).
    """
    body = parent.add("body", name=name, pos=pos, euler=(0.0, 0.0, yaw) if yaw else None)
    for k, g in enumerate(template.geoms):
        body.add("geom", name=f"{name}_{g.get('name') or k}", dclass=geom_class_name(template, k))
    return body
