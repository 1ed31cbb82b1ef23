"""INI reading with errors that name the file, the line and the key.

configparser does the parsing; a light scan of the same text records the line
of every section header and key so that a bad value can be reported as
``kleeman-lab.ini:42: [beacon3] x_m: not a number: 'abc'``.
"""
from __future__ import annotations

import configparser
import math
import re
from pathlib import Path

_SECTION_RE = re.compile(r"^\s*\[([^\]]+)\]")
_KEY_RE = re.compile(r"^\s*([^=:;#\s][^=:]*?)\s*[=:]")


class ConfigError(ValueError):
    """A bad site or scenario file; the message names file, line and key."""


class IniFile:
    """One parsed INI file; typed getters raise ConfigError naming file:line."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.name = self.path.name
        try:
            text = self.path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"{self.path}: cannot read: {exc.strerror or exc}") from exc
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{self.path}: not UTF-8 text: {exc}") from exc
        self._lines: dict[tuple[str, str | None], int] = {}
        section = None
        for number, line in enumerate(text.splitlines(), start=1):
            if line.lstrip().startswith((";", "#")):
                continue
            match = _SECTION_RE.match(line)
            if match:
                section = match.group(1).strip()
                self._lines.setdefault((section, None), number)
                continue
            match = _KEY_RE.match(line)
            if match and section is not None and not line[:1].isspace():
                self._lines.setdefault((section, match.group(1).strip().lower()), number)
        self._overridden: set[tuple[str, str]] = set()
        self.parser = configparser.ConfigParser(
            inline_comment_prefixes=(";", "#"), interpolation=None, strict=True)
        try:
            self.parser.read_string(text, source=str(self.path))
        except configparser.DuplicateOptionError as exc:
            raise ConfigError(f"{self.name}:{exc.lineno}: [{exc.section}] {exc.option}: "
                              "duplicate key") from exc
        except configparser.DuplicateSectionError as exc:
            raise ConfigError(f"{self.name}:{exc.lineno}: [{exc.section}]: duplicate section") from exc
        except configparser.MissingSectionHeaderError as exc:
            raise ConfigError(f"{self.name}:{exc.lineno}: key before any [section]: "
                              f"{exc.line.strip()!r}") from exc
        except configparser.ParsingError as exc:
            lineno, line = exc.errors[0] if exc.errors else (0, "")
            raise ConfigError(f"{self.name}:{lineno}: cannot parse line: {line.strip()!r}") from exc

    # -- locations -------------------------------------------------------
    def override(self, section: str, key: str, value: str) -> None:
        """Set [section] key = value as if the file said so (a command line's --set); its
        errors then name the option: ``file: --set [section] key: ...``."""
        if not self.parser.has_section(section):
            self.parser.add_section(section)
        self.parser.set(section, key, value)
        self._overridden.add((section, key.lower()))

    def where(self, section: str, key: str | None = None) -> str:
        """``file:line: [section] key`` for messages (line of the section if the key is absent)."""
        if key is not None and (section, key.lower()) in self._overridden:
            return f"{self.name}: --set [{section}] {key}"
        line = self._lines.get((section, key.lower() if key else None)) \
            or self._lines.get((section, None))
        loc = f"{self.name}:{line}" if line else f"{self.name}"
        return f"{loc}: [{section}]" + (f" {key}" if key else "")

    def error(self, section: str, key: str | None, why: str) -> ConfigError:
        return ConfigError(f"{self.where(section, key)}: {why}")

    # -- typed getters ---------------------------------------------------
    def has(self, section: str, key: str | None = None) -> bool:
        if key is None:
            return self.parser.has_section(section)
        return self.parser.has_option(section, key)

    def raw(self, section: str, key: str, default: str | None = None) -> str:
        if not self.parser.has_section(section):
            if default is not None:
                return default
            raise ConfigError(f"{self.name}: [{section}]: missing section (needed for key {key})")
        if not self.parser.has_option(section, key):
            if default is not None:
                return default
            raise self.error(section, key, "missing key")
        return self.parser.get(section, key).strip()

    def number(self, section: str, key: str, default: float | None = None, *,
               minimum: float | None = None, maximum: float | None = None,
               positive: bool = False) -> float:
        text = self.raw(section, key, None if default is None else repr(float(default)))
        value = self._to_float(section, key, text)
        self._check_range(section, key, value, minimum, maximum, positive)
        return value

    def integer(self, section: str, key: str, default: int | None = None, *,
                minimum: int | None = None, maximum: int | None = None) -> int:
        text = self.raw(section, key, None if default is None else str(int(default)))
        try:
            value = int(text, 0)
        except ValueError:
            raise self.error(section, key, f"not an integer: {text!r}") from None
        self._check_range(section, key, value, minimum, maximum, False)
        return value

    def numbers(self, section: str, key: str, count: int | None = None,
                default: list[float] | None = None) -> list[float]:
        """A comma-separated list of numbers (exactly ``count`` of them if given)."""
        if default is not None and not self.has(section, key):
            return list(default)
        text = self.raw(section, key)
        parts = [p.strip() for p in text.split(",") if p.strip()]
        values = [self._to_float(section, key, p) for p in parts]
        if count is not None and len(values) != count:
            raise self.error(section, key, f"expected {count} comma-separated numbers, got "
                             f"{len(values)}: {text!r}")
        return values

    def _to_float(self, section: str, key: str, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise self.error(section, key, f"not a number: {text!r}") from None
        if not math.isfinite(value):
            raise self.error(section, key, f"not a finite number: {text!r}")
        return value

    def _check_range(self, section, key, value, minimum, maximum, positive):
        if positive and not value > 0:
            raise self.error(section, key, f"must be > 0, got {value:g}")
        if minimum is not None and value < minimum:
            raise self.error(section, key, f"must be >= {minimum:g}, got {value:g}")
        if maximum is not None and value > maximum:
            raise self.error(section, key, f"must be <= {maximum:g}, got {value:g}")

    def check_known(self, section: str, known: set[str]) -> None:
        """Unknown keys in a section we own are errors (a typo must not pass silently)."""
        if not self.parser.has_section(section):
            return
        for key in self.parser.options(section):
            if key not in known and key not in self.parser.defaults():
                raise self.error(section, key, "unknown key (known: " + ", ".join(sorted(known)) + ")")
