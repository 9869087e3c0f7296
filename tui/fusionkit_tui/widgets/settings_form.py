"""The merge settings: method, Algorithm 1 and eq. 2 thresholds, the PSO swarm, the seed.

Each value is checked as it is typed (the field turns red and the hint says what is allowed);
:meth:`SettingsForm.config` turns the fields into a :class:`fusionkit.pipeline.MergeConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from rich.text import Text
from textual import on
from textual.binding import Binding
from textual.app import ComposeResult
from textual.containers import Grid, VerticalScroll
from textual.validation import ValidationResult, Validator
from textual.widgets import Checkbox, Input, Label, Select, Static

from fusionkit.errors import InputError
from fusionkit.pipeline import METHODS, MergeConfig

__all__ = ["Setting", "SETTINGS", "SettingsForm", "parse_setting"]


@dataclass(frozen=True)
class Setting:
    """One numeric setting of the form.

    ``kind`` is ``"int"`` or ``"float"``; ``lo``/``hi`` bound it (inclusive); ``optional``
    allows a blank field (meaning "not set"); ``default`` is shown beside it.
    """

    key: str
    label: str
    kind: str
    lo: float
    hi: float
    default: object
    help: str
    optional: bool = False

    def allowed(self) -> str:
        what = "a whole number" if self.kind == "int" else "a number"

        def show(v) -> str:
            # whole numbers in full (a seed's bound read 9.22337e+18)
            return f"{int(v)}" if self.kind == "int" else f"{v:g}"

        lo = "" if math.isinf(self.lo) else show(self.lo)
        hi = "" if math.isinf(self.hi) else show(self.hi)
        if lo and hi:
            rng = f" from {lo} to {hi}"
        elif lo:
            rng = f" >= {lo}"
        elif hi:
            rng = f" <= {hi}"
        else:
            rng = ""
        return what + rng + (" or blank" if self.optional else "")


#: The method selected at start: the paper's, whose swarm the convergence plot follows
#: (``consensus``, the library's default, verifies placements instead and is one pick away).
TUI_METHOD = "spectral-pso"


#: What each method is, in one line of the form
_METHOD_HINTS = {
    "spectral-pso": "the paper's DFT + Pearson + PSO; the Run tab plots its swarm",
    "consensus": "the library's default; verified placements, refused when unsure",
    "map-merge": "a classic peer: AKAZE features + RANSAC, as multirobot_map_merge",
    "map-merge-shipped": "a classic peer: multirobot_map_merge as shipped",
    "hough-spectrum": "a classic peer: the rotation from the walls' Hough spectra",
    "fourier-mellin": "a classic peer: phase correlation of the maps' spectra",
}


def method_hint(method: str) -> str:
    """The form's line about ``method`` (its default marked)."""
    return f"default {TUI_METHOD}: {_METHOD_HINTS[TUI_METHOD]}" if method == TUI_METHOD else \
        f"{method}: {_METHOD_HINTS.get(method, '')}"


def used_settings(method: str) -> set[str]:
    """The keys of the settings ``method`` reads (the others are dimmed in the form)."""
    if method == "spectral-pso":
        return {s.key for s in SETTINGS if s.help.startswith("spectral-pso")} | {"seed", "seeding"}
    return {"max_false_merge", "seed"}   # consensus, and the peers: theirs is the consensus test


def _settings() -> tuple[Setting, ...]:
    d = MergeConfig()
    p = d.pso
    inf = math.inf
    return (
        Setting("theta", "theta", "float", -1, 1, d.theta,
                "spectral-pso: Pearson rho above which two unique poses agree (eq. 2)"),
        Setting("unique_count", "unique poses", "int", 1, 100000, d.unique_count,
                "spectral-pso: unique poses per robot (Algorithm 1); sets delta"),
        Setting("delta", "delta", "float", 0, inf, None,
                "spectral-pso: fixed divergence threshold (m x beams); blank: from unique poses",
                optional=True),
        Setting("sub_sec", "sub-section", "int", 1, 1000, d.sub_sec,
                "spectral-pso: half-width of Algorithm 1's sections (poses)"),
        Setting("particles", "particles", "int", 1, 10000, p.particles, "spectral-pso: PSO swarm size"),
        Setting("iterations", "iterations", "int", 0, 100000, p.iterations,
                "spectral-pso: PSO iterations (at most)"),
        Setting("w", "w", "float", 0, 10, p.w, "spectral-pso: PSO inertia weight"),
        Setting("c1", "c1", "float", 0, 10, p.c1, "spectral-pso: PSO cognitive coefficient"),
        Setting("c2", "c2", "float", 0, 10, p.c2, "spectral-pso: PSO social coefficient"),
        Setting("accept", "accept", "float", 0, 1, d.accept,
                "spectral-pso: least wall agreement for a map to be merged (fraction)"),
        Setting("max_false_merge", "merge risk", "float", 1e-300, 0.999, d.max_false_merge,
                "consensus: the false-merge risk accepted (--max-false-merge)"),
        Setting("seed", "seed", "int", 0, 2**63 - 1, d.seed, "seed of every random step"),
    )


#: The numeric settings, in form order.
SETTINGS = _settings()


def _setting_of(widget) -> Setting | None:
    """The setting a form field (``#set-KEY``) edits, or None."""
    key = (widget.id or "").removeprefix("set-")
    return next((s for s in SETTINGS if s.key == key), None)


def parse_setting(s: Setting, text: str):
    """The value of ``text`` for setting ``s``.

    Raises
    ------
    InputError
        When ``text`` is not allowed; the message names the setting and what it must be.
    """
    t = text.strip()
    if not t:
        if s.optional:
            return None
        raise InputError(f"{s.label}: is empty; type {s.allowed()} (default {s.default})")
    try:
        v = int(t) if s.kind == "int" else float(t)
    except ValueError:
        raise InputError(f"{s.label}: {t!r} is not {s.allowed()}") from None
    if not math.isfinite(v) or not s.lo <= v <= s.hi:
        raise InputError(f"{s.label}: {t} is out of range; type {s.allowed()}")
    return v


class _SettingValidator(Validator):
    def __init__(self, setting: Setting) -> None:
        super().__init__()
        self.setting = setting

    def validate(self, value: str) -> ValidationResult:
        try:
            parse_setting(self.setting, value)
        except InputError as exc:
            return self.failure(str(exc).split(": ", 1)[-1])
        return self.success()


def _default_text(s: Setting) -> str:
    return "" if s.default is None else f"{s.default:g}" if isinstance(s.default, float) else str(s.default)


_SEEDING = ("default on: spectral-pso starts the swarm also at the transforms of matched scans; "
            "off: the paper's blind search")
_NOTE = ("tab moves into the fields (or click one) and shows the field's help in full here; escape "
         "or enter leaves a field; an invalid value turns red and blocks the run; 1-4 switch "
         "tabs, r runs (ctrl+r while typing).")


class SettingsForm(VerticalScroll, can_focus=True):
    """Every merge setting with its default; invalid values are flagged as they are typed.

    The form itself takes the focus when its tab is shown, so the app's keys (``1``-``4``,
    ``r``, ``q``) keep working; a field takes text only once it is clicked or tabbed into, and
    leaving it (escape, enter, tab, a click elsewhere) checks its value.
    """

    BINDINGS = [
        Binding("escape", "leave_field", "Done"),
        Binding("ctrl+r", "run_from_field", "Run"),
    ]

    DEFAULT_CSS = """
    SettingsForm {
        height: 1fr;
        padding: 0 1;
    }
    SettingsForm > Grid {
        grid-size: 3;
        grid-columns: 13 21 1fr;
        grid-rows: 1;
        grid-gutter: 0 1;
        height: auto;
    }
    SettingsForm Label {
        width: 100%;
        text-align: right;
        color: $text-muted;
    }
    SettingsForm Input {
        width: 100%;
    }
    SettingsForm Input.-invalid {
        background: $error 35%;
    }
    SettingsForm Select {
        width: 100%;
    }
    SettingsForm Checkbox {
        width: 100%;
    }
    SettingsForm .unused {
        opacity: 45%;
    }
    SettingsForm .hint {
        color: $text-muted;
        width: 100%;
        height: 1;
        text-wrap: nowrap;
        text-overflow: ellipsis;
    }
    SettingsForm .hint.-invalid {
        color: $text-error;
        text-style: bold;
    }
    SettingsForm #settings-note {
        margin-top: 1;
        color: $text-muted;
        height: auto;
    }
    """

    def compose(self) -> ComposeResult:
        with Grid():
            yield Label("method")
            yield Select([(m, m) for m in METHODS], value=TUI_METHOD, allow_blank=False,
                         compact=True, id="method")
            yield Static(method_hint(TUI_METHOD), id="hint-method", classes="hint")
            for s in SETTINGS:
                yield Label(s.label, id=f"label-{s.key}")
                yield Input(_default_text(s), id=f"set-{s.key}", compact=True, valid_empty=s.optional,
                            validators=[_SettingValidator(s)], select_on_focus=False)
                default = "blank" if s.default is None else _default_text(s)
                yield Static(f"default {default}: {s.help}", id=f"hint-{s.key}", classes="hint")
            yield Label("seeding", id="label-seeding")
            yield Checkbox("on", MergeConfig().alignment.seeded, id="seeding", compact=True)
            yield Static(_SEEDING, id="hint-seeding", classes="hint")
        yield Static(_NOTE, id="settings-note")

    @on(Checkbox.Changed, "#seeding")
    def _on_seeding(self, event: Checkbox.Changed) -> None:
        """The box says what it is set to (its mark alone hardly shows, without colour least)."""
        event.checkbox.label = "on" if event.value else "off"

    @on(Select.Changed, "#method")
    def _on_method(self, event: Select.Changed) -> None:
        """The method's own words, and the settings it does not read dimmed."""
        method = str(event.value)
        self.query_one("#hint-method", Static).update(method_hint(method))
        if event.select.has_focus:
            self._describe(event.select)
        used = used_settings(method)
        for key in [s.key for s in SETTINGS] + ["seeding"]:
            field = "#seeding" if key == "seeding" else f"#set-{key}"
            for part in (f"#label-{key}", field, f"#hint-{key}"):
                self.query_one(part).set_class(key not in used, "unused")

    def on_descendant_focus(self, event) -> None:
        self._describe(event.widget)

    def _field(self) -> Input | None:
        f = self.screen.focused if self.is_attached else None
        return f if isinstance(f, Input) and self in f.ancestors else None

    def check_action(self, action: str, parameters: tuple) -> bool | None:
        # only while a field is typed into; otherwise escape and ctrl+r are the screen's
        if action in ("leave_field", "run_from_field"):
            return self._field() is not None
        return True

    def action_run_from_field(self) -> None:
        field = self._field()
        s = _setting_of(field) if field is not None else None
        if s is not None:
            try:
                parse_setting(s, field.value)
            except InputError:
                # leaving the field says what is wrong with it; the run would say it again
                self.focus()
                return
        self.screen.action_run()

    def action_leave_field(self) -> None:
        """Give the keys back to the app (the value is checked as the field loses focus)."""
        if self._field() is not None:
            self.focus()

    @on(Input.Submitted)
    def _on_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.focus()

    @on(Input.Blurred)
    def _on_blurred(self, event: Input.Blurred) -> None:
        s = _setting_of(event.input)
        if s is None:
            return
        try:
            value = parse_setting(s, event.input.value)
        except InputError as exc:
            self._hint(s, str(exc).split(": ", 1)[-1])
            event.input.add_class("-invalid")
            self.notify(f"{exc}; the merge will not run until it is fixed",
                        title="Check the settings", severity="error", timeout=6)
            return
        default = s.default
        if value != default:
            was = "blank" if default is None else _default_text(s)
            now = "blank" if value is None else event.input.value.strip()
            self.query_one(f"#hint-{s.key}", Static).update(
                Text.assemble((f"set to {now}", "bold"), f" (default {was}): {s.help}"))

    def _describe(self, widget) -> None:
        """Say in full what the field ``widget`` is, and what is wrong with its value."""
        key = (widget.id or "").removeprefix("set-")
        note = self.query_one("#settings-note", Static)
        for s in SETTINGS:
            if s.key == key and isinstance(widget, Input):
                default = "blank" if s.default is None else _default_text(s)
                text = Text(f"{s.label}: {s.help}; {s.allowed()}, default {default}.\n")
                try:
                    parse_setting(s, widget.value)
                except InputError as exc:
                    text.append(f"{exc}\n", style="bold red")
                text.append(_NOTE)
                note.update(text)
                return
        select = next((w for w in widget.ancestors_with_self if isinstance(w, Select)), None)
        if select is not None and select.id == "method":   # the field or its open list
            note.update(Text(f"method: {method_hint(str(select.value))}\n").append(_NOTE))
            return
        if widget.id == "seeding":
            note.update(Text(f"seeding: {_SEEDING}\n").append(_NOTE))
            return
        note.update(_NOTE)

    def _hint(self, s: Setting, failure: str | None) -> None:
        hint = self.query_one(f"#hint-{s.key}", Static)
        default = "blank" if s.default is None else _default_text(s)
        if failure:
            hint.update(Text(f"{failure}", style=""))
            hint.add_class("-invalid")
        else:
            hint.update(f"default {default}: {s.help}")
            hint.remove_class("-invalid")

    @on(Input.Changed)
    def _on_changed(self, event: Input.Changed) -> None:
        key = (event.input.id or "").removeprefix("set-")
        for s in SETTINGS:
            if s.key == key:
                v = event.validation_result
                self._hint(s, None if v is None or v.is_valid else "; ".join(v.failure_descriptions))
                if event.input.has_focus:
                    self._describe(event.input)
                return

    def set_value(self, key: str, text: str) -> None:
        """Type ``text`` into the field of setting ``key`` (validated like keyboard input)."""
        self.query_one(f"#set-{key}", Input).value = text

    def values(self) -> dict:
        """The settings as ``{key: value}`` (plus ``method`` and ``seeded``).

        Raises
        ------
        InputError
            For the first field that holds an invalid value.
        """
        out = {"method": self.query_one("#method", Select).value,
               "seeded": self.query_one("#seeding", Checkbox).value}
        for s in SETTINGS:
            out[s.key] = parse_setting(s, self.query_one(f"#set-{s.key}", Input).value)
        return out

    def config(self, reference: int = 0) -> MergeConfig:
        """The :class:`MergeConfig` the form describes, with map ``reference`` as the reference.

        Raises
        ------
        InputError
            An invalid field (named in the message) or a combination the pipeline refuses.
        """
        v = self.values()
        cfg = MergeConfig(method=v["method"], theta=v["theta"], unique_count=v["unique_count"],
                          delta=v["delta"], sub_sec=v["sub_sec"], accept=v["accept"],
                          reference=reference, seed=v["seed"],
                          max_false_merge=v["max_false_merge"])
        cfg = cfg.with_pso(particles=v["particles"], iterations=v["iterations"], w=v["w"],
                           c1=v["c1"], c2=v["c2"])
        if v["seeded"] != cfg.alignment.seeded:
            cfg = replace(cfg, alignment=replace(cfg.alignment, seeded=v["seeded"]))
        return cfg
