"""The nsplug macro preprocessor, as MOOS-IvP missions use it (spec: docs/spec/mission-files.md section 3).

Real missions are kept as `meta_*.moos` / `meta_*.bhv` templates; nsplug expands them before launch.
`preprocess` does the same in memory and keeps, for every output line, the file and line it came
from, so a later parse error still names the template line the user has to fix.

Faithful quirks (kept on purpose, the missions depend on them):
* a line that still holds `$(` or `%(` after substitution is emitted in its original, unexpanded
  form (helm macros such as `$(PX)` in a .bhv pass through); `strict=True` makes that an error;
* inside a *tagged* include every line starting with `#` is dropped, so both branches of an
  `#ifdef` in a tagged section reach the output;
* in an `&&` conjunction, `A x` with A and x both undefined is true (both look up as empty).

Deliberate differences: include loops are detected and reported; an unclosed `#ifdef` and a stray
`#else`/`#endif` are errors; a `#word` close to a directive name (a typo such as `#inclde`) is an
error, while other `#` lines (comments in a .bhv) pass through as nsplug passes them.
"""
from __future__ import annotations

import argparse
import difflib
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from .formats import print_page, version_page
from .source import MissionFileError, SourceLine

MAX_SUBSTITUTIONS = 100
DIRECTIVES = ("#include", "#define", "#ifdef", "#ifndef", "#elseifdef", "#else", "#endif")
_MACRO = re.compile(r"([$%])\(([^()$%]*)\)")


class Macros:
    """The one shared macro table: defines made inside an include stay visible after it.

    A name maps to its value, or to None when it was defined bare (`NAME` on the command line,
    `#define NAME`), which nsplug treats as "defined" for `#ifdef` and as empty for `$(NAME)`.
    """

    def __init__(self, defines: dict[str, str | None] | None = None):
        self.table: dict[str, str | None] = dict(defines or {})

    def define(self, name: str, value: str | None) -> None:
        self.table[name] = value

    def is_defined(self, name: str) -> bool:
        return name in self.table

    def value(self, name: str) -> str:
        return self.table.get(name) or ""

    def is_set(self, name: str) -> bool:
        """`#ifdef NAME` truth: defined bare, or with a non-empty value."""
        return name in self.table and self.table[name] != ""

    def expand(self, text: str) -> str:
        """Substitute macros until nothing changes (at most MAX_SUBSTITUTIONS per line)."""
        for _ in range(MAX_SUBSTITUTIONS):
            match = next((m for m in _MACRO.finditer(text) if self._resolve(m) is not None), None)
            if match is None:
                return text
            text = text[: match.start()] + self._resolve(match) + text[match.end():]
        return text

    def _resolve(self, match: re.Match) -> str | None:
        sigil, body = match.group(1), match.group(2)
        name, default, colon = body, None, False
        eq = body.find("=")
        if eq >= 0:
            colon = eq > 0 and body[eq - 1] == ":"
            name, default = body[: eq - 1 if colon else eq], body[eq + 1:]
        name = name.strip()
        if self.value(name) != "":
            value = self.value(name)
        elif default is None:
            if not self.is_defined(name):
                return None
            value = ""
        else:  # defined-but-empty gives "" for NAME=dflt and the default for NAME:=dflt
            value = "" if self.is_defined(name) and not colon else default
        return value.upper() if sigil == "%" else value


@dataclass
class _Branch:
    """One #ifdef level: whether the enclosing text is live, and whether a branch was taken."""

    opened: SourceLine
    parent_live: bool
    taken: bool
    live: bool


@dataclass
class _Context:
    macros: Macros
    include_paths: tuple[Path, ...]
    strict: bool
    lenient: bool = False
    stack: list[Path] = field(default_factory=list)


def preprocess(path, defines: dict[str, str | None] | None = None, include_paths=(), strict: bool = False,
               tag: str | None = None, lenient: bool = False) -> list[SourceLine]:
    """Expand an nsplug template into its lines, each tagged with its original file and line.

    `defines` are the command-line macros (`VAR=value`; a None value is a bare `VAR`). Includes are
    looked up in the including file's folder, then in `include_paths`, then in the current working
    directory (nsplug's own `.`). `tag` selects one `<tag>` section of the top-level file, as
    nsplug's `--tag`; `lenient` emits partially expanded lines (nsplug's `-l`). Raises
    MissionFileError naming file:line.
    """
    context = _Context(Macros(defines), tuple(Path(p) for p in include_paths), strict, lenient)
    path = Path(path)
    if not path.is_file():
        raise MissionFileError(path, 0, "file not found")
    return _expand_file(path, context, tag)


def _read_lines(path: Path, where: SourceLine | None) -> list[str]:
    try:
        # split, not splitlines: nsplug emits one empty line more at the end of every file
        return [line.rstrip("\r") for line in path.read_text(encoding="latin-1").split("\n")]
    except OSError as exc:
        if where is None:
            raise MissionFileError(path, 0, f"cannot read: {exc.strerror}") from exc
        raise MissionFileError.at(where, f"cannot read include {path}: {exc.strerror}") from exc


def _tag_name(text: str) -> str | None:
    """`<tag><pShare>` -> `pShare`; None for a line that is not a tag line."""
    stripped = text.strip()
    if not stripped.startswith("<tag>"):
        return None
    return stripped[len("<tag>"):].strip().strip("<>").strip()


def _tag_section(lines: list[str], tag: str) -> list[tuple[int, str]]:
    """The lines after `<tag><TAG>` up to the next `<tag>` line (numbered from 1).

    A tag the file does not have gives nothing, as in nsplug: m2_berta includes `plugs.moos <iM300>`
    under `#elseifdef XMODE M300` although plugs.moos has no such section.
    """
    section, inside = [], False
    for number, text in enumerate(lines, 1):
        name = _tag_name(text)
        if name is not None:
            inside = name == tag
        elif inside:
            section.append((number, text))
    return section


def _expand_file(path: Path, context: _Context, tag: str | None, where: SourceLine | None = None) -> list[SourceLine]:
    resolved = path.resolve()
    if resolved in context.stack:
        chain = " -> ".join(p.name for p in [*context.stack, resolved])
        raise MissionFileError.at(where, f"include loop: {chain}")
    lines = _read_lines(path, where)
    context.stack.append(resolved)
    try:
        if tag is not None:
            section = _tag_section(lines, tag)
            # QUIRK (spec 3.6): directive lines of a tagged section are dropped, not obeyed.
            return [_emit(SourceLine(text, path, number), context)
                    for number, text in section if not text.lstrip().startswith("#")]
        return _expand_lines(path, lines, context)
    finally:
        context.stack.pop()


def _expand_lines(path: Path, lines: list[str], context: _Context) -> list[SourceLine]:
    out: list[SourceLine] = []
    branches: list[_Branch] = []
    for number, text in enumerate(lines, 1):
        src = SourceLine(text, path, number)
        live = not branches or branches[-1].live
        words = text.replace("\t", " ").split()
        word = words[0] if words else ""
        if word in DIRECTIVES:
            _directive(src, word, text.replace("\t", " ").strip()[len(word):].strip(), branches, live, context, out)
        elif _tag_name(text) is not None:
            continue
        elif live:
            _reject_typo(src, word)
            out.append(_emit(src, context))
    if branches:
        raise MissionFileError.at(branches[-1].opened, "#ifdef/#ifndef without matching #endif")
    return out


def _reject_typo(src: SourceLine, word: str) -> None:
    if re.fullmatch(r"#[A-Za-z]+", word):
        close = difflib.get_close_matches(word.lower(), DIRECTIVES, n=1, cutoff=0.75)
        if close:
            raise MissionFileError.at(src, f"unknown nsplug directive '{word}' (did you mean {close[0]}?)")


def _directive(src: SourceLine, word: str, rest: str, branches: list[_Branch], live: bool,
               context: _Context, out: list[SourceLine]) -> None:
    macros = context.macros
    if word in ("#ifdef", "#ifndef"):
        if not rest:
            raise MissionFileError.at(src, f"{word} needs a macro name")
        truth = _ifdef(src, rest, context) if word == "#ifdef" else not any(macros.is_set(n) for n in rest.split())
        branches.append(_Branch(src, live, truth, live and truth))
        return
    if word in ("#elseifdef", "#else", "#endif") and not branches:
        raise MissionFileError.at(src, f"{word} without #ifdef")
    if word == "#elseifdef":
        top = branches[-1]
        truth = not top.taken and _ifdef(src, rest, context)
        top.taken, top.live = top.taken or truth, top.parent_live and truth
    elif word == "#else":
        top = branches[-1]
        top.live, top.taken = top.parent_live and not top.taken, True
    elif word == "#endif":
        branches.pop()
    elif not live:
        return
    elif word == "#define":
        _define(src, rest, macros)
    elif word == "#include":
        out.extend(_include(src, rest, context))


def _define(src: SourceLine, rest: str, macros: Macros) -> None:
    parts = rest.split(None, 1)
    if not parts:
        raise MissionFileError.at(src, "#define needs a macro name")
    name = parts[0]
    if name.startswith("$(") and name.endswith(")"):
        name = name[2:-1]
    macros.define(name, " ".join(parts[1].split()) if len(parts) > 1 else None)


def _include(src: SourceLine, rest: str, context: _Context) -> list[SourceLine]:
    rest = context.macros.expand(rest)
    match = re.fullmatch(r'"([^"]+)"\s*(<[^<>]+>)?|(\S+)\s*(<[^<>]+>)?', rest)
    if not rest or match is None:
        raise MissionFileError.at(src, f"#include expects a file name and an optional <tag>, got '{rest}'")
    name = match.group(1) or match.group(3)
    tag = (match.group(2) or match.group(4) or "").strip("<>").strip() or None
    if "$(" in name or "%(" in name:
        raise MissionFileError.at(src, f"#include file name '{name}' has an undefined macro")
    for folder in (src.file.parent, *context.include_paths, Path(os.getcwd())):
        candidate = Path(name) if Path(name).is_absolute() else folder / name
        if candidate.is_file():
            return _expand_file(candidate, context, tag, src)
    searched = ", ".join(str(p) for p in (src.file.parent, *context.include_paths, Path(os.getcwd())))
    raise MissionFileError.at(src, f"#include file '{name}' not found (searched {searched})")


def _ifdef(src: SourceLine, rest: str, context: _Context) -> bool:
    has_or, has_and = "||" in rest, "&&" in rest
    if has_or and has_and:
        if context.strict:
            raise MissionFileError.at(src, "#ifdef mixes || and &&")
        return False
    clauses = [c.split() for c in re.split(r"\|\||&&", rest)]
    if any(not c for c in clauses):
        raise MissionFileError.at(src, f"#ifdef has an empty clause: '{rest}'")
    macros = context.macros
    if has_and:
        return all(macros.is_defined(c[0]) if len(c) == 1 else _matches(macros, c, conjunction=True) for c in clauses)
    return any(macros.is_set(c[0]) if len(c) == 1 else _matches(macros, c, conjunction=False) for c in clauses)


def _matches(macros: Macros, clause: list[str], conjunction: bool) -> bool:
    name, wanted = clause[0], " ".join(clause[1:])
    if not conjunction and not macros.is_defined(name):
        return False
    value = macros.value(name)
    if value == wanted:
        return True
    return (conjunction or macros.is_defined(wanted)) and value == macros.value(wanted)


def _emit(src: SourceLine, context: _Context) -> SourceLine:
    expanded = context.macros.expand(src.text)
    if "$(" in expanded or "%(" in expanded:
        if context.strict and not src.text.lstrip().startswith("//"):
            raise MissionFileError.at(src, f"unexpanded macro in: {expanded.strip()}")
        if not context.lenient:
            return src  # QUIRK (spec 3.3): the whole line stays in its original form
    return SourceLine(expanded, src.file, src.line)


def parse_defines(pairs) -> dict[str, str | None]:
    """`VAR=value` / bare `VAR` words (nsplug's command-line form) into a defines table."""
    table: dict[str, str | None] = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not name:
            raise ValueError(f"bad macro definition '{pair}': expected VAR=value")
        table[name] = value if sep else None
    return table


def read_macro_file(path: Path) -> dict[str, str | None]:
    """nsplug's `--macros=file`: `NAME=value` (or bare `NAME`) lines; `#` and `//` lines are comments."""
    lines = [t.strip() for t in path.read_text(encoding="latin-1").splitlines()]
    return parse_defines(t for t in lines if t and not t.startswith(("#", "//")))


EXAMPLE = """\
// meta_vehicle.moos: expanded with  nsplug meta_vehicle.moos targ_abe.moos -f VNAME=abe PORT=9001
ServerPort = $(PORT)
Community  = $(VNAME)
// another template, searched in the template's folder and the --path / -p folders
#include plug_origin_warp.moos
#ifdef VNAME abe
  START_POS = 0,-20
#else
  START_POS = 50,-20
#endif
"""
INTERFACE = """\
nsplug is a preprocessor, not a MOOS client: it subscribes to nothing and publishes nothing.
It reads a template (macros $(NAME) and %(NAME), #include, #define, #ifdef/#ifndef/#else/#endif)
and writes the expanded file, or prints it with -t.
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="nsplug", description="Expand an nsplug template (meta_*.moos/.bhv) "
                                "as MOOS-IvP's nsplug does: nsplug infile outfile [options] [MACRO=value ...]")
    p.add_argument("infile")
    p.add_argument("words", nargs="*", metavar="outfile MACRO=value",
                   help="the output file (unless -t), then macros: NAME=value, or a bare NAME (defined, empty)")
    p.add_argument("-f", "--force", action="store_true", help="overwrite the output file without asking")
    p.add_argument("-i", "--interactive", action="store_true", help="ask before overwriting (the default)")
    p.add_argument("-t", "--terminal", action="store_true", help="print to stdout instead of an output file")
    p.add_argument("-s", "--strict", action="store_true", help="fail on any unexpanded macro")
    p.add_argument("-l", "--lenient", action="store_true", help="emit partially expanded lines")
    p.add_argument("--path", default="", help="include folders, colon-separated")
    p.add_argument("-p", dest="folders", action="append", default=[],
                   help="an include folder (repeatable; unlike MOOS-IvP's -p it consumes its argument)")
    p.add_argument("--tag", help="expand only this <tag> section of the input")
    p.add_argument("--macros", type=Path, help="a file of NAME=value lines")
    p.add_argument("--example", action="store_true", help="print an example template and its command line")
    p.add_argument("--interface", action="store_true", help="print what nsplug reads and writes")
    p.add_argument("--version", action="version", version=version_page("nsplug"), help="print the release")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    for page, text in (("--example", EXAMPLE), ("--interface", INTERFACE)):
        if page in argv:   # before parsing: these need no template file
            print_page(text)
            return 0
    args = _parser().parse_intermixed_args(argv)
    words = list(args.words)
    out = None if args.terminal else (Path(words.pop(0)) if words else None)
    try:
        if out is None and not args.terminal:
            raise ValueError("an output file is needed (or -t for the terminal)")
        defines = read_macro_file(args.macros) if args.macros else {}
        defines.update(parse_defines(words))
        folders = [p for p in args.path.split(":") if p] + args.folders
        lines = preprocess(args.infile, defines, folders, strict=args.strict,
                           tag=args.tag, lenient=args.lenient)
    except (OSError, ValueError) as exc:   # MissionFileError is a ValueError: file:line: message
        print(f"nsplug: {exc}", file=sys.stderr)
        return 1
    text = "".join(line.text + "\n" for line in lines)
    if out is None:
        sys.stdout.write(text)
        return 0
    if out.exists() and not args.force:
        answer = input(f"nsplug: {out} exists. Overwrite? [y/N] ") if sys.stdin.isatty() else ""
        if answer.strip().lower() not in ("y", "yes"):
            print(f"nsplug: {out} exists; not overwritten (use -f)", file=sys.stderr)
            return 1
    out.write_text(text, encoding="latin-1")
    return 0
