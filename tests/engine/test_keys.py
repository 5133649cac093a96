"""The override-key grammar: every form read into an OverrideKey, every bad key refused naming what is allowed."""

import pytest

from warpdem.engine.keys import PER_WORLD, VARY, KeyGrammar, OverrideKey

# a scene-like grammar: what warpdem.scene.stage.OVERRIDES adds, plus rig parameters
SCENE = KeyGrammar(
    {
        "material": ("density", "poisson_ratio", "youngs_modulus", "shear_modulus"),
        "interaction": ("restitution", "static_friction", "law"),
        "run": ("duration", "clump_contact_mass"),
        "measure": ("base_height",),
        "factory": ("count", "rate"),
        "rig": ("count", "particle_radius"),
    }
)
DEFINED = {"material": ["grain", "steel"], "factory": ["pour"]}

VALID = [
    (SCENE, "material.grain.density", OverrideKey("material", ("grain",), "density")),
    (SCENE, "interaction.grain.steel.law", OverrideKey("interaction", ("grain", "steel"), "law")),
    (SCENE, "run.clump_contact_mass", OverrideKey("run", (), "clump_contact_mass")),
    (SCENE, "measure.base_height", OverrideKey("measure", (), "base_height")),
    (SCENE, "factory.pour.rate", OverrideKey("factory", ("pour",), "rate")),
    (SCENE, "particle_radius", OverrideKey("rig", (), "particle_radius")),
    (VARY, "gravity", OverrideKey("gravity")),
    (VARY, "interaction.grain.grain.restitution", OverrideKey("interaction", ("grain", "grain"), "restitution")),
    (KeyGrammar({"rig": None}), "anything_at_all", OverrideKey("rig", (), "anything_at_all")),
]


@pytest.mark.parametrize("grammar, text, key", VALID, ids=[v[1] for v in VALID])
def test_valid_keys_parse(grammar, text, key):
    """Each form reads into its kind, names and field, and str() gives the key back."""
    parsed = grammar.parse(text, "test", defined=DEFINED)
    assert parsed == key
    assert str(parsed) == text
    assert grammar.accepts(text, DEFINED)


INVALID = [
    # (grammar, key, substrings the message must contain)
    (SCENE, "", ["key = ''", "a non-empty string"]),
    (SCENE, 3, ["key = 3", "a non-empty string"]),
    (SCENE, "material.grain.densty", ["a material field", "density", "did you mean 'density'"]),
    (SCENE, "material.grain", ["material.NAME.FIELD (one of"]),
    (SCENE, "material..density", ["material.NAME.FIELD"]),
    (SCENE, "interaction.grain.static_friction", ["interaction.A.B.FIELD"]),
    (SCENE, "interaction.grian.steel.law", ["material 'grian' is not defined", "did you mean 'grain'", "grain, steel"]),
    (SCENE, "interaction.grain.stel.law", ["material 'stel' is not defined"]),
    (SCENE, "factory.pur.rate", ["factory 'pur' is not defined", "did you mean 'pour'"]),
    (SCENE, "factory.pour.mass", ["a factory setting: count, rate"]),
    (SCENE, "run.duraton", ["a run setting", "did you mean 'duration'"]),
    (SCENE, "mesure.base_height", ["one of material.NAME.FIELD", "a rig parameter", "did you mean 'measure'"]),
    (SCENE, "partcle_radius", ["a rig parameter", "did you mean 'particle_radius'", "or one of material.NAME"]),
    (SCENE, "gravity", ["a rig parameter: count, particle_radius"]),
    (VARY, "interaction.grain.grain.lw", ["an interaction field", "restitution", "did you mean 'law'"]),
    (VARY, "run.duration", ["one of material.NAME.FIELD, interaction.A.B.FIELD or gravity"]),
    (VARY, "gravty", ["did you mean 'gravity'"]),
    (PER_WORLD, "gravity", ["one of material.NAME.FIELD or interaction.A.B.FIELD"]),
]


@pytest.mark.parametrize("grammar, text, needles", INVALID, ids=[repr(v[1]) for v in INVALID])
def test_invalid_keys_refused(grammar, text, needles):
    """A bad key raises the caller's error naming where it came from, the key and what is allowed."""

    class CallerError(ValueError):
        pass

    assert not grammar.accepts(text, DEFINED)
    with pytest.raises(CallerError) as err:
        grammar.parse(text, "[fixed]", defined=DEFINED, error=CallerError)
    msg = str(err.value)
    assert msg.startswith("[fixed]: key = ") and "is not allowed; expected" in msg
    for needle in needles:
        assert needle in msg, f"{needle!r} not in {msg!r}"


def test_names_unchecked_without_defined():
    """Without the scene's names a key's material and factory names are taken as written (a study checks
    them later, against the scene it builds)."""
    assert SCENE.parse("interaction.a.b.law", "test") == OverrideKey("interaction", ("a", "b"), "law")


def test_per_world_fields():
    """Material fields and every interaction field (the law and rolling model too) vary per world; a run
    setting, a rig parameter or gravity (a builder variation, not an override) does not."""
    assert PER_WORLD.accepts("material.grain.youngs_modulus")
    assert PER_WORLD.accepts("interaction.a.b.tangential_stiffness_multiplier")
    assert PER_WORLD.accepts("interaction.a.b.law")
    assert PER_WORLD.accepts("interaction.a.b.rolling_model")
    for text in ("run.duration", "count", "gravity"):
        assert not PER_WORLD.accepts(text), text
