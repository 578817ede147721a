"""Reusable models of ``models/`` (package ``garage_mj.models``) as stamps for scene builders.

``dm_control.mjcf`` attach is the textbook way to reuse a model, but attaching a hundred parked
cars costs about a second (a deep copy and a namespace per car). A scene instead copies a model's
default classes and materials once, then stamps its body per placement: a body named after the
placement (``parkedcar_12``) holding the model's geoms, which keep the model's classes. The
semantic class still comes from the body name (:mod:`garage_mj.semantics`).
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


def class_name(template: Template, local: str | None) -> str | None:
    """Scene-wide name of a template-local class (prefixed unless it is the model's own class)."""
    if local is None:
        return None
    return local if local == template.name else f"{template.name}_{local}"


def material_name(template: Template, local: str | None) -> str | None:
    return None if local is None else f"{template.name}_{local}"


def install(root: mjcf.RootElement, template: Template) -> None:
    """Copy ``template``'s default classes and materials into ``root`` (once per scene)."""
    made = {}
    for dclass, parent, attrs in template.defaults:
        holder = root.default if parent is None else made[parent]
        d = holder.add("default", dclass=class_name(template, dclass))
        if attrs:
            d.geom.set_attributes(**attrs)
        made[dclass] = d
    for name, attrs in template.materials:
        root.asset.add("material", name=material_name(template, name), **attrs)


def stamp(parent, template: Template, name: str, pos, yaw: float, *, name_geoms: bool = True):
    """Add one instance of ``template`` under ``parent`` as a body called ``name``; returns the body.

    Angles are radians (the scene sets ``compiler angle="radian"``). Geoms are named
    ``<name>_<geom>`` so contacts and segmentation read as the instance's class.
    """
    body = parent.add(
        "body", name=name, pos=pos, euler=[0.0, 0.0, yaw] if yaw else None,
        childclass=class_name(template, template.childclass),
    )
    for g in template.geoms:
        attrs = dict(g)
        attrs["dclass"] = class_name(template, attrs.get("dclass"))
        if "material" in attrs:
            attrs["material"] = material_name(template, attrs["material"])
        gname = attrs.pop("name", None)
        if name_geoms and gname:
            attrs["name"] = f"{name}_{gname}"
        body.add("geom", **attrs)
    return body
