"""Values with units in a config: the pass that turns a model written in physical units into the
nondimensional config the schema checks and the solver runs.

A config with a ``scaling`` section (:class:`convection.physics.scaling.ScalingSettings`) may write
any quantity as ``<number> <unit>`` (``3300 kg/m^3``, ``1e21 Pa s``, ``9.81 m/s^2``, ``100 km``,
``10 Myr``, ``1600 K``, ``5 cm/yr``). Before the schema checks it, :func:`apply_scaling` rewrites it:

- a value with a unit becomes the solver's number, ``q / scale`` by its dimension
  (:meth:`Scaling.nondimensional`); a temperature *value* (a boundary temperature ``dirichlet``,
  a law's ``T_ref``, a constant of ``initial.constants``, ``initial.temperature`` written as one
  value) counts from the reference temperature: ``(T - T0) / dT``;
- a number without a unit is nondimensional, as in every nondimensional config (so those keep
  working unchanged, and a scaled model may still give, e.g., a law's exponent as a number);
- ``materials.<name>.density`` becomes that material's ``Rb = (rho - rho0) g L^3 / (eta0 kappa)``
  (``rho0``: scaling.density, the background's density);
- ``physics.Ra`` follows from the scaling (``rho0 alpha dT g L^3 / (eta0 kappa)``) when
  ``scaling.thermal_expansivity`` is given; a model without the energy equation needs none;
- ``phase_transitions.<name>``: the depth, width and temperature (a value) as any quantity, the
  Clapeyron slope (a pressure per temperature) as ``clapeyron dT / (rho0 g L)``, the
  ``density_jump`` (a fraction of rho0) as the transition's ``Rb``, the ``entropy_change`` in J/kg/K
  over ``c_p`` (``clausius_clapeyron``: ``clapeyron density_jump / (rho0 c_p)``);
- ``physics.reference`` of a compressible approximation (``eba``, ``tala``, ``ala``): ``Di = alpha g L /
  c_p`` from the scaling (``thermal_expansivity``, ``gravity``, ``heat_capacity``) when not given, the
  surface temperature ``T0 = T_ref / dT``, the ``potential_temperature`` as a temperature value, and
  the ``profile``'s depths as lengths and its thermal expansivity and heat capacity (1/K, J/kg/K)
  over the scaling's (``alpha0``, ``c_p0``): the reference state of physical parameters
  (:class:`convection.physics.compressible.ReferenceProfile`);
- ``physics.H`` in W/kg becomes ``H t0 / (c_p dT)``; as a heating rate (K/s, K/Myr) it is scaled
  as any quantity;
- expressions (initial conditions, material regions, particle densities and properties) stay
  text; in a scaled model they may use the unit constants ``m``, ``km``, ``s``, ``yr``, ``kyr``,
  ``Myr`` and ``K`` (the nondimensional value of one of each: ``"z > 1 - 100*km"``).

The result keeps the ``scaling`` section (the output units come from it) and is itself a valid
config: written to a run folder and read again (a restart), it gives the same model.
"""

from __future__ import annotations

import copy
import math
import re
from typing import Any

from convection.physics.compressible import APPROXIMATIONS
from convection.physics.scaling import Scaling, ScalingSettings, looks_like_quantity, parse_quantity, registry
from convection.schema import ConfigError, key_text, section_schema, short_repr, validate

__all__ = ["apply_scaling", "in_written_terms", "scaling_of", "written_quantities"]

_NUMBERS = ("Ra", "Rb")
"""Keys that are nondimensional numbers by definition (a unit there is a mistake)."""


_VISCOSITY, _STRESS = "[mass] / [length] / [time]", "[mass] / [length] / [time] ** 2"
EXPECTED: dict[str, str] = {
    **dict.fromkeys(("end", "dt_max", "dt_initial", "every_time"), "[time]"),
    **dict.fromkeys(("upper", "lower", "radii", "resolution", "entrainment_height", "depth_ref", "width"), "[length]"),
    **dict.fromkeys(("dirichlet", "T_ref", "T_offset", "potential_temperature"), "[temperature]"),
    **dict.fromkeys(("background", "viscosity", "eta0", "eta_star", "min_viscosity", "max_viscosity",
                     "material_viscosities"), _VISCOSITY),
    **dict.fromkeys(("yield_stress", "cohesion", "shear_modulus"), _STRESS),
    **dict.fromkeys(("reference_strain_rate", "steady_state_rate"), "1 / [time]"),
    "steady_state_time_window": "[time]",
    "elastic_time_step": "[time]",
    "H": "[temperature] / [time]",
}
"""The dimension a value with a unit must have, by the name of its key (a key not named here takes
any dimension)."""


def _absolute(path: tuple[str, ...]) -> bool:
    """Whether the value at ``path`` is a temperature value (counted from T0), not a difference."""
    return path[-1] in ("dirichlet", "T_ref", "potential_temperature") or path[:2] == ("initial", "constants") \
        or path == ("initial", "temperature")


def _first_quantity(node: Any, path: tuple[str, ...] = ()) -> tuple[str, str] | None:
    """The dotted key and text of the first value with a unit in a document, or None."""
    if isinstance(node, dict):
        for name, value in node.items():
            found = _first_quantity(value, (*path, key_text(name)))
            if found:
                return found
    elif isinstance(node, list):
        for i, value in enumerate(node):
            found = _first_quantity(value, (*path[:-1], f"{path[-1]}[{i}]") if path else (f"[{i}]",))
            if found:
                return found
    elif parse_quantity(node) is not None:
        return ".".join(path), node
    return None


def written_quantities(node: Any, path: tuple[str, ...] = ()) -> dict[str, str]:
    """Every value with a unit in a document, by its dotted key (the key :func:`apply_scaling`
    reports it under; list items share their list's key), as written."""
    if isinstance(node, dict):
        return {k: v for name, value in node.items()
                for k, v in written_quantities(value, (*path, key_text(name))).items()}
    if isinstance(node, list):
        return {k: v for value in node for k, v in written_quantities(value, path).items()}
    return {".".join(path): node} if parse_quantity(node) is not None else {}


_KEY = re.compile(r"config key '([^']+)'")


def in_written_terms(err: ConfigError, written: dict[str, str], document: dict[str, Any], /) -> ConfigError:
    """``err`` (raised on the nondimensional ``document``) with the value of the key it names as the
    user wrote it: a check sees ``-99.99999999999999`` where the config says ``-1e23 Pa s``."""
    message = str(err)
    match = _KEY.search(message)
    if match is None or match.group(1) not in written:
        return err
    text = written[match.group(1)]
    node: Any = document
    for part in match.group(1).split("."):
        node = node.get(part) if isinstance(node, dict) else None
    if isinstance(node, (int, float)) and not isinstance(node, bool):
        for shown in dict.fromkeys((short_repr(node), repr(node), str(node), f"{node:.6g}")):
            if f"got {shown}" in message:
                return ConfigError(message.replace(f"got {shown}", f"got {text}"))
    return ConfigError(f"{message} (written: {text})")


def _convert(node: Any, scaling: Scaling, path: tuple[str, ...]) -> Any:
    """``node`` with every value with a unit made nondimensional (module docstring)."""
    if isinstance(node, dict):
        return {name: _convert(value, scaling, (*path, key_text(name))) for name, value in node.items()}
    if isinstance(node, list):
        return [_convert(value, scaling, path) for value in node]
    quantity = parse_quantity(node)
    key = ".".join(path)
    if quantity is None:
        if looks_like_quantity(node) and path[:1] != ("initial",) and "initial" not in path:
            raise ConfigError(f"config key '{key}': {short_repr(node)} is not a number with a unit pint knows "
                              "(e.g. 660 km, 1e21 Pa s, 10 Myr, 5 cm/yr)")
        return node
    if path and path[-1] in _NUMBERS:
        raise ConfigError(f"config key '{key}': a nondimensional number; in a model with units give the "
                          "materials' densities (materials.<name>.density) or the scaling's thermal expansivity")
    expected = EXPECTED.get(path[-1].split("[")[0]) if path else None
    if path[:2] == ("boundary", "velocity"):
        expected = "[length] / [time]"
    if expected is not None and quantity.dimensionality != registry().get_dimensionality(expected):
        raise ConfigError(f"config key '{key}': {short_repr(node)} is not of {expected} (its dimension: "
                          f"{quantity.dimensionality})")
    if quantity.dimensionless:
        return float(quantity.to("").magnitude)
    value = scaling.nondimensional(quantity, absolute=_absolute(path))
    return repr(value) if path == ("initial", "temperature") else value


def _densities(document: dict[str, Any], scaling: Scaling) -> None:
    """Each material's density -> its Rb (in place)."""
    materials = document.get("materials")
    if not isinstance(materials, dict):
        return
    for name, spec in materials.items():
        if not isinstance(spec, dict) or spec.get("density") is None:
            continue
        key = f"materials.{key_text(name)}"
        if "Rb" in spec:
            raise ConfigError(f"config key '{key}.Rb': not with {key}.density (the density gives Rb)")
        quantity = parse_quantity(spec["density"])
        if quantity is None or quantity.dimensionality != registry().get_dimensionality("[mass] / [length] ** 3"):
            raise ConfigError(f"config key '{key}.density': expected a density with a unit (e.g. 3300 kg/m^3), got "
                              f"{short_repr(spec['density'])}")
        rho = float(quantity.to("kg/m^3").magnitude)
        spec["Rb"] = scaling.buoyancy_number(rho - scaling.needed("density"))
        del spec["density"]


def _free_surface(document: dict[str, Any], scaling: Scaling) -> None:
    """free_surface.buoyancy, the weight of the reference density in the surface's load, from
    ``rho0 g L^3 / (eta0 kappa)`` where a boundary is a free surface and it is not given (in place)."""
    velocity = (document.get("boundary") or {}).get("velocity") if isinstance(document.get("boundary"), dict) else None
    if not isinstance(velocity, dict) or "free_surface" not in velocity.values():
        return
    section = document.setdefault("free_surface", {})
    if isinstance(section, dict) and section.get("buoyancy") is None and scaling.density is not None \
            and scaling.gravity is not None:
        section["buoyancy"] = scaling.buoyancy_number(scaling.needed("density"))


def _phase_transitions(document: dict[str, Any], scaling: Scaling) -> None:
    """Each phase transition's values with units -> its nondimensional keys (module docstring; in place)."""
    transitions = document.get("phase_transitions")
    if not isinstance(transitions, dict):
        return
    for name, spec in transitions.items():
        if not isinstance(spec, dict):
            continue
        key = f"phase_transitions.{key_text(name)}"
        for item, dimension in (("depth", "[length]"), ("width", "[length]"), ("temperature", "[temperature]")):
            quantity = _phase_quantity(spec, item, key, dimension)
            if quantity is not None:
                spec[item] = scaling.nondimensional(quantity, absolute=item == "temperature")
        slope = _phase_quantity(spec, "clapeyron", key, "[mass] / [length] / [time] ** 2 / [temperature]")
        jump = spec.get("density_jump")
        if jump is not None:
            quantity = parse_quantity(jump)
            jump = float(quantity.to("").magnitude) if quantity is not None and quantity.dimensionless else jump
            if not isinstance(jump, (int, float)) or isinstance(jump, bool):
                raise ConfigError(f"config key '{key}.density_jump': expected a fraction (e.g. 0.08), got "
                                  f"{short_repr(spec['density_jump'])}")
            if "Rb" in spec:
                raise ConfigError(f"config key '{key}.Rb': not with {key}.density_jump (the density jump gives Rb)")
            spec["Rb"] = scaling.buoyancy_number(jump * scaling.needed("density"))
            del spec["density_jump"]
        slope_si = float(slope.to("Pa/K").magnitude) if slope is not None else None
        if spec.get("entropy_change") == "clausius_clapeyron":
            if slope_si is None or jump is None:
                raise ConfigError(f"config key '{key}.entropy_change': clausius_clapeyron needs the clapeyron slope "
                                  "with a unit (e.g. -2.5 MPa/K) and the density_jump")
            spec["entropy_change"] = slope_si * jump / (scaling.needed("density") * scaling.needed("heat_capacity"))
        else:
            entropy = _phase_quantity(spec, "entropy_change", key, "[length] ** 2 / [time] ** 2 / [temperature]")
            if entropy is not None:
                spec["entropy_change"] = float(entropy.to("J/kg/K").magnitude) / scaling.needed("heat_capacity")
        if slope_si is not None:
            spec["clapeyron"] = slope_si * scaling.needed("temperature_difference") / (
                scaling.needed("density") * scaling.needed("gravity") * scaling.length)
    if any(isinstance(s, dict) and s.get("entropy_change") for s in transitions.values()):
        physics = document.setdefault("physics", {})
        reference = physics.setdefault("reference", {}) if isinstance(physics, dict) else None
        if isinstance(reference, dict) and "surface_temperature" not in reference:
            # the absolute temperature T + T_s of the latent heat: T_s = T0 / dT
            reference["surface_temperature"] = scaling.reference_temperature / scaling.needed("temperature_difference")


_PHASE_DIMENSIONS = {"[length]": "a length (e.g. 660 km)", "[temperature]": "a temperature (e.g. 1900 K)",
                     "[mass] / [length] / [time] ** 2 / [temperature]": "a pressure per temperature (e.g. -2.5 MPa/K)",
                     "[length] ** 2 / [time] ** 2 / [temperature]": "an entropy per mass (e.g. 60 J/kg/K)"}


def _phase_quantity(spec: dict[str, Any], item: str, key: str, dimension: str) -> Any:
    """The quantity of ``spec[item]`` when it has a unit (of ``dimension``, else refused), or None."""
    quantity = parse_quantity(spec.get(item))
    if quantity is None:
        return None
    if quantity.dimensionality != registry().get_dimensionality(dimension):
        raise ConfigError(f"config key '{key}.{item}': {short_repr(spec[item])} is not {_PHASE_DIMENSIONS[dimension]}")
    return quantity


_PROFILE = {"depth": ("[length]", None), "thermal_expansivity": ("1 / [temperature]", "thermal_expansivity"),
            "heat_capacity": ("[length] ** 2 / [time] ** 2 / [temperature]", "heat_capacity")}
"""The columns of ``physics.reference.profile``: their dimension and the scaling value they are taken over
(None: the length scale)."""


def _reference(document: dict[str, Any], scaling: Scaling) -> None:
    """``physics.reference`` of a compressible approximation from the scaling (module docstring; in place)."""
    physics = document.get("physics")
    if not isinstance(physics, dict):
        return  # _physics made it, or the schema reports it
    reference = physics.get("reference")
    if isinstance(reference, dict) and isinstance(reference.get("profile"), dict):
        _reference_profile(reference["profile"], scaling)
    name = str(physics.get("approximation", "boussinesq"))
    if name not in APPROXIMATIONS or not APPROXIMATIONS[name].dissipation:
        return
    reference = physics.setdefault("reference", {})
    if not isinstance(reference, dict):
        return  # the schema reports it
    given = reference.get("Di")
    if None not in (scaling.thermal_expansivity, scaling.gravity, scaling.heat_capacity):
        Di = scaling.dissipation_number()
        if given is not None and not (isinstance(given, (int, float)) and math.isclose(given, Di, rel_tol=1e-12)):
            raise ConfigError(f"config key 'physics.reference.Di': {short_repr(given)} given, but the scaling gives "
                              f"Di = {Di:.6g} (alpha g L / c_p); give one or the other")
        reference["Di"] = Di
    elif given is None:
        raise ConfigError(f"config key 'physics.reference.Di': physics.approximation {name} needs a dissipation "
                          "number; give it, or scaling.thermal_expansivity, gravity and heat_capacity (Di = alpha g L "
                          "/ c_p)")
    T0 = scaling.reference_temperature / scaling.needed("temperature_difference")
    surface = reference.get("surface_temperature", T0)
    quantity = parse_quantity(surface)
    if quantity is not None and quantity.dimensionality == registry().get_dimensionality("[temperature]"):
        surface = float(quantity.to("K").magnitude) / scaling.needed("temperature_difference")
    if not (isinstance(surface, (int, float)) and math.isclose(float(surface), T0, rel_tol=1e-12, abs_tol=1e-15)):
        raise ConfigError(f"config key 'physics.reference.surface_temperature': {short_repr(surface)} given, but in a "
                          f"model with units it is scaling.reference_temperature / temperature_difference = "
                          f"{T0:.6g}; leave it out")
    reference["surface_temperature"] = T0


def _reference_profile(profile: dict[str, Any], scaling: Scaling) -> None:
    """The profile's values with units -> nondimensional (over L, alpha0, c_p0; in place)."""
    for column, (dimension, over) in _PROFILE.items():
        values = profile.get(column)
        if not isinstance(values, list):
            continue
        key = f"physics.reference.profile.{column}"
        converted = []
        for value in values:
            quantity = parse_quantity(value)
            if quantity is None:
                converted.append(value)  # a number: nondimensional already (the schema checks it)
                continue
            if quantity.dimensionality != registry().get_dimensionality(dimension):
                raise ConfigError(f"config key '{key}': {short_repr(value)} is not of {dimension} (e.g. "
                                  f"{_PROFILE_EXAMPLES[column]})")
            si = float(quantity.to_base_units().magnitude)
            converted.append(si / (scaling.length if over is None else scaling.needed(over)))
        profile[column] = converted


_PROFILE_EXAMPLES = {"depth": "660 km", "thermal_expansivity": "2e-5 1/K", "heat_capacity": "1250 J/kg/K"}


def _physics(document: dict[str, Any], scaling: Scaling) -> None:
    """physics.Ra from the scaling; physics.H in W/kg (in place)."""
    physics = document.get("physics")
    if physics is None:
        physics = document["physics"] = {}
    if not isinstance(physics, dict):
        return  # the schema reports it
    heating = parse_quantity(physics.get("H"))
    if heating is not None and heating.dimensionality == registry().get_dimensionality("[length] ** 2 / [time] ** 3"):
        rate = heating / registry().Quantity(scaling.needed("heat_capacity"), "J/kg/K")
        physics["H"] = scaling.nondimensional(rate.to("K/s"))
    if scaling.thermal_expansivity is None:
        return
    Ra = scaling.rayleigh()
    given = physics.get("Ra")
    if given is not None and not (isinstance(given, (int, float)) and math.isclose(float(given), Ra, rel_tol=1e-12)):
        raise ConfigError(f"config key 'physics.Ra': {short_repr(given)} given, but the scaling gives Ra = {Ra:.6g} "
                          "(rho0 alpha dT g L^3 / (eta0 kappa)); give one or the other")
    physics["Ra"] = Ra


def apply_scaling(document: dict[str, Any]) -> dict[str, Any]:
    """The nondimensional document of ``document`` (module docstring); a document without a
    ``scaling`` section is returned as it is, unless it has a value with a unit.

    Raises:
        ConfigError: one line naming the key: a value with a unit without a scaling, a unit of the
            wrong dimension, a scale the model needs that is missing, Ra or Rb given twice.
    """
    schema = section_schema(ScalingSettings)
    checked = validate(schema, document.get("scaling"), prefix="scaling.")
    if checked == validate(schema, {}):  # no scaling (or its defaults, as a written config has them)
        found = _first_quantity({name: value for name, value in document.items() if name != "scaling"})
        if found is not None:
            raise ConfigError(f"config key '{found[0]}': {short_repr(found[1])} has a unit; a model with units needs "
                              "the scaling section (scaling.length, scaling.viscosity, ...)")
        return document
    scaling = Scaling.from_section(checked)
    result = copy.deepcopy(document)
    _densities(result, scaling)
    _physics(result, scaling)
    _free_surface(result, scaling)
    _phase_transitions(result, scaling)
    _reference(result, scaling)
    converted = {name: value if name == "scaling" else _convert(value, scaling, (key_text(name),))
                 for name, value in result.items()}
    return converted


_CACHE: dict[str, Scaling] = {}


def scaling_of(config: dict[str, Any]) -> Scaling | None:
    """The :class:`Scaling` of a resolved config (None: a nondimensional model). Cached by the
    section's text (expressions ask for it often)."""
    section = config.get("scaling") or {}
    if section.get("length") is None:
        return None
    key = repr(sorted((k, repr(v)) for k, v in section.items()))
    if key not in _CACHE:
        _CACHE[key] = Scaling.from_section(section)
    return _CACHE[key]
