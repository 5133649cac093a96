"""Override keys: the one grammar of the keys that set a value of a model or a scene from outside.

::

    material.NAME.FIELD      a numeric Material field of material NAME
    interaction.A.B.FIELD    an Interaction field of the pair of materials A and B
    run.FIELD                a run setting of the scene
    measure.FIELD            a measurement setting of the scene
    factory.NAME.FIELD       a setting of factory NAME
    gravity                  the gravity vector
    PARAMETER                any other word without a dot: a parameter of the rig the scene was made from

A :class:`KeyGrammar` says which of these forms one caller takes and which FIELDs (or rig parameters) each
allows: :meth:`warpdem.engine.builder.ModelBuilder.vary` takes :data:`VARY`; ``warpdem run --set`` takes
:data:`warpdem.scene.stage.OVERRIDES`, which adds the scene's run, measure and factory fields (the engine does
not import the scene, so the scene passes its lists in); a study adds its rig's parameters.
:meth:`KeyGrammar.parse` reads a key into an :class:`OverrideKey` or refuses it with one message format that
names where the key came from, the key and what is allowed, with a "did you mean" for a misspelt word.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .checks import did_you_mean, fail
from .materials import INTERACTION_FIELDS, MATERIAL_SCALARS


@dataclass(frozen=True)
class KeyKind:
    """One kind of key: how it is written (``form``), what messages call its FIELDs (``label``) and what
    its NAME parts name (``names``: "material", "factory"; none for most kinds)."""

    form: str
    label: str = ""
    names: tuple[str, ...] = ()

    @property
    def dotted(self) -> bool:
        return "." in self.form


KINDS = {
    "material": KeyKind("material.NAME.FIELD", "a material field", ("material",)),
    "interaction": KeyKind("interaction.A.B.FIELD", "an interaction field", ("material", "material")),
    "run": KeyKind("run.FIELD", "a run setting"),
    "measure": KeyKind("measure.FIELD", "a measurement setting"),
    "factory": KeyKind("factory.NAME.FIELD", "a factory setting", ("factory",)),
    "gravity": KeyKind("gravity"),
    "rig": KeyKind("a rig parameter", "a rig parameter"),
}
"""Every kind of key, in the order messages list them."""

_DOTTED = tuple(k for k, kind in KINDS.items() if kind.dotted)


@dataclass(frozen=True)
class OverrideKey:
    """A key read by :meth:`KeyGrammar.parse`: its ``kind`` (a key of :data:`KINDS`), the ``names`` it
    addresses (one material, two materials, a factory, or none) and the ``field`` it sets (the parameter for
    a rig key, "" for gravity). ``str()`` gives the key back."""

    kind: str
    names: tuple[str, ...] = ()
    field: str = ""

    def __str__(self) -> str:
        if self.kind == "gravity":
            return "gravity"
        if self.kind == "rig":
            return self.field
        return ".".join((self.kind, *self.names, self.field))


@dataclass(frozen=True)
class KeyGrammar:
    """The keys one caller takes.

    Attributes:
        fields: kind (a key of :data:`KINDS`) -> the FIELDs allowed for it; for "rig" the parameter names,
            or None to take any word without a dot (a rig not known yet); for "gravity" an empty tuple.
            Kinds not in it are refused.
        labels: what a message calls the FIELDs of a kind, where the default ("an interaction field", ...)
            is not right (e.g. "a numeric interaction field").
    """

    fields: Mapping[str, Sequence[str] | None]
    labels: Mapping[str, str] = field(default_factory=dict)

    def parse(
        self,
        key,
        where: str,
        name: str = "key",
        defined: Mapping[str, Sequence[str]] | None = None,
        error: type[ValueError] = ValueError,
    ) -> OverrideKey:
        """Read ``key``, or raise ``error`` saying ``{where}: {name} = {key!r} is not allowed; expected ...``.

        ``defined`` maps "material" / "factory" to the names defined in the scene or model; a key naming
        another one is refused (names are not checked for a kind it does not list)."""
        parsed, allowed = self._read(key, defined or {})
        if parsed is None:
            fail(where, name, key, allowed, error)
        return parsed

    def accepts(self, key, defined: Mapping[str, Sequence[str]] | None = None) -> bool:
        """True when :meth:`parse` reads ``key``."""
        return self._read(key, defined or {})[0] is not None

    def forms(self, kinds=None) -> str:
        """How the keys of ``kinds`` (default: all this grammar takes) are written, "a, b or c"."""
        words = [kind.form for k, kind in KINDS.items() if k in self.fields and (kinds is None or k in kinds)]
        return ", ".join(words[:-1]) + " or " + words[-1] if len(words) > 1 else "".join(words)

    def _read(self, key, defined) -> tuple[OverrideKey | None, str]:
        """(the key read, "") or (None, what is allowed instead)."""
        if not isinstance(key, str) or not key:
            return None, "a non-empty string"
        head, *rest = key.split(".")
        if not rest:
            if key == "gravity" and "gravity" in self.fields:
                return OverrideKey("gravity"), ""
            if "rig" in self.fields:
                return self._field("rig", (), key)
            return None, f"one of {self.forms()}{did_you_mean(key, [k for k in self.fields if k not in _DOTTED])}"
        if head not in _DOTTED or head not in self.fields:
            return None, f"one of {self.forms()}{did_you_mean(head, [k for k in _DOTTED if k in self.fields])}"
        named = KINDS[head].names
        if len(rest) != len(named) + 1 or not all(rest):
            return None, f"{KINDS[head].form} (one of {self.forms()})"
        for kind, word in zip(named, rest):
            known = defined.get(kind)
            if known is not None and word not in known:
                return None, (
                    f"names of defined {kind}s: {kind} {word!r} is not defined{did_you_mean(word, known)}; "
                    f"defined: {', '.join(known) or 'none'}"
                )
        return self._field(head, tuple(rest[:-1]), rest[-1])

    def _field(self, kind: str, names: tuple[str, ...], word: str) -> tuple[OverrideKey | None, str]:
        allowed = self.fields[kind]
        if allowed is None or word in allowed:
            return OverrideKey(kind, names, word), ""
        text = f"{self.labels.get(kind, KINDS[kind].label)}: {', '.join(allowed)}{did_you_mean(word, allowed)}"
        if kind == "rig":
            text += f"; or one of {self.forms(_DOTTED)}"
        return None, text


def is_rig_key(key: str) -> bool:
    """True for a key that names a rig parameter (``count``): a word without a dot, the ``rig`` form of
    :data:`KINDS`. A scene regenerates from its rig for these before the dotted keys apply."""
    return "." not in key


PER_WORLD = KeyGrammar({"material": MATERIAL_SCALARS, "interaction": INTERACTION_FIELDS})
"""The keys whose values can differ between the worlds of one model: numeric material fields and every
interaction field, the pair's law and rolling model included (each world has its own pair table, and the
kernels dispatch on a pair's law per contact)."""

VARY = KeyGrammar({**PER_WORLD.fields, "gravity": ()}, PER_WORLD.labels)
"""The keys of :meth:`warpdem.engine.builder.ModelBuilder.vary`: :data:`PER_WORLD` and gravity."""
