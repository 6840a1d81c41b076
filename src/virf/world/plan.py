"""Parse plans written in SafeAgentBench's action language, or in everyday words.

Accepted per line (case-insensitive verbs; blank lines and ``#`` comments are
skipped, leading numbering such as ``3.`` or ``3)`` is ignored)::

    find X            pick X | pick up X       put R | put X in R | put X on R
    open X            close X                  turn_on X | turn on X | toggle on X
    turn_off X ...    slice X   break X   cook X   dirty X   clean X
    fillLiquid X water|coffee|wine             emptyLiquid X
    pour | pour X     drop | drop X            throw | throw X

and the function style of the paper's walkthrough: ``put_in(Pot_1, Microwave_1)``.
A plan file may also be a JSON list of such strings.  ``throw X`` and ``drop
X`` name the object held; the simulator refuses the step if it is not.

Everyday phrasings (``light the candle``, ``blow it out``, ``grab the pot``,
``set it down on the table``) are read as one action each through the one
table :data:`virf.world.language.EVERYDAY`, longest phrase first, and the
step's ``note`` says how (the report lists the notes); a line in the action
language gets no note.
``it`` and ``them`` stand for the held object where the action needs one,
else for the one object of the step before.  A line that could be read two
ways (``turn the stove``, ``set the cup``, ``take the apple out of the
fridge``) is an input error naming the problem and the valid phrasings, never
a guess.  docs/planner.md lists the table and the rules.

Limits (docs/reliability.md): at most ``MAX_PLAN_STEPS`` actions and
``MAX_LINE_CHARS`` characters per action line; control and invisible
characters, and empty arguments in the function style, are input errors.

Objects may be named in words, as SafeAgentBench's reference plans and LLM
replies do: ``find dining table``, ``turn off coffee machine``, ``pick up the
knives``, ``find stove knob 2``, ``the lit candle``.  The parser only groups
the words into object terms; which type or instance a term names (and which
instance a leading state word such as ``lit`` chooses,
:data:`virf.world.language.STATE_ADJECTIVES`) is the simulator's decision,
since only it knows the vocabulary and the scene.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path

from virf.errors import InputError, clip, closest, hidden_char, parse_json, read_input_file
from virf.names import term_key
from virf.world.language import (
    ACTION_CLASS,
    ALIASES,
    ARITY,
    EVERYDAY,
    LANGUAGE_PHRASES,
    LIQUIDS,
    ON_OFF_HEADS,
    PARTICLES,
    VERBS,
    Reading,
)

# Words that stand for the object of the step before.
PRONOUNS = frozenset({"it", "them"})
# What 'pour water into the sink' pours: the held object's liquid.
_LIQUID_WORDS = frozenset({*LIQUIDS, "liquid", "contents"})


def _phrasebook() -> dict[str, list[tuple[tuple[str, ...], Reading, bool]]]:
    """Every phrasing by its first word, longest first: (words, reading, everyday)."""
    book: dict[str, list[tuple[tuple[str, ...], Reading, bool]]] = {}
    entries = [
        *((phrase, Reading(verb), False) for phrase, verb in LANGUAGE_PHRASES.items()),
        *((phrase, reading, True) for phrase, reading in EVERYDAY.items()),
    ]
    for phrase, reading, everyday in entries:
        words = tuple(phrase.split())
        book.setdefault(words[0], []).append((words, reading, everyday))
    for options in book.values():
        options.sort(key=lambda o: -len(o[0]))
    return book


_PHRASEBOOK = _phrasebook()
# Words that can open an action line (for finding a plan inside prose).
ACTION_WORDS = frozenset(ALIASES) | frozenset(_PHRASEBOOK) | set(ON_OFF_HEADS)
_NUMBERING = re.compile(r"^\s*(?:step\s*)?\d+\s*[.):]\s*", re.IGNORECASE)
_CALL = re.compile(r"^([A-Za-z_]+)\s*\((.*)\)\s*$")
_CONNECTORS = {"in", "into", "inside", "on", "onto", "over", "to"}
_ARTICLES = {"the", "a", "an"}
# Words of manner in everyday lines ('put the vinegar back on the shelf',
# 'carefully pick up the glass'): they name no object and change no action.
_MANNER = {"back", "please", "carefully", "gently", "slowly", "quickly", "again", "then", "now"}
# A word of an object name written in words ("dining", "Table", "watering-can").
# Anything else (Apple_1, Mug2, "apple,") is a name on its own.
_PLAIN_WORD = re.compile(r"^[A-Za-z]+(?:['-][A-Za-z]+)*$")
# The longest catalogue names have three words ("toilet paper hanger"); a
# longer run of words is prose ("open the fridge door slowly"), not a name.
MAX_NAME_WORDS = 3
# Far above any household task (SafeAgentBench's longest reference plans have a
# few dozen steps), far below what would overrun a verification deadline.
MAX_PLAN_STEPS = 1_000
# A plan line names a verb and at most two objects; a longer line is pasted
# prose or garbage, and every name in it would be fuzzy-matched against the scene.
MAX_LINE_CHARS = 1_000


def singular_forms(term: str) -> tuple[str, ...]:
    """Singular readings of a name that may be plural ('apples' -> 'apple',
    'knives' -> 'knif', 'knife'); the caller keeps the ones that name something."""
    low = term.lower()
    out: list[str] = []
    if low.endswith("ies"):
        out.append(term[:-3] + "y")
    if low.endswith("ves"):
        out += [term[:-3] + "f", term[:-3] + "fe"]
    if low.endswith("es"):
        out.append(term[:-2])
    if low.endswith("s") and not low.endswith("ss"):
        out.append(term[:-1])
    return tuple(o for o in out if len(term_key(o)) > 1)


@dataclass(frozen=True)
class PlanStep:
    index: int  # 1-based
    text: str  # the line as written
    verb: str  # canonical verb
    args: tuple[str, ...]
    # How an everyday phrasing was read ('light the candle' -> 'turn_on candle');
    # None when the line is in the action language itself.
    note: str | None = None
    # The object the line says is poured from ('pour the mug into the sink'):
    # it must be the object the agent holds.  ``throw X`` and ``drop X`` name
    # theirs as their argument.
    held: str | None = None

    @property
    def action_class(self) -> str:
        return ACTION_CLASS[self.verb]

    def canonical(self) -> str:
        return " ".join((self.verb, *self.args))

    @property
    def held_term(self) -> str | None:
        """The words naming the object this step needs in the hand, if the
        line names it ('throw AlarmClock', 'pour the mug into the sink')."""
        if self.verb in ("drop", "throw") and self.args:
            return self.args[0]
        return self.held


def _unknown_verb(word: str, line_no: int) -> InputError:
    spellings = [*(a for a in ALIASES if "_" not in a), *LANGUAGE_PHRASES, *EVERYDAY]
    near = closest(word, spellings)
    hint = f"; closest: {', '.join(near)}" if near else ""
    return InputError(
        f"plan line {line_no}: unknown action '{word}'{hint}; valid verbs: {', '.join(VERBS)}"
        f"; everyday phrasings: {', '.join(EVERYDAY)}"
    )


def _is_number(token: str) -> bool:
    # isdigit alone accepts '²', which int() refuses: only ASCII digits count.
    return token.isascii() and token.isdigit() and int(token) > 0


def _name(words: list[str]) -> str:
    # SafeAgentBench numbers instances of one type: "find Mug 2" means Mug_2.
    # A numbered name in words stays in words ("stove knob 2"); the simulator
    # compares it with StoveKnob_2 through term_key.
    if len(words) == 2 and _is_number(words[1]):
        return f"{words[0]}_{words[1]}"
    return " ".join(words)


def _terms(tokens: list[str], max_words: int = MAX_NAME_WORDS) -> list[str]:
    """Group a line's words into object names: a run of plain words (closed by
    an instance number) is one name; an identifier such as Apple_1 stands alone."""
    out: list[str] = []
    run: list[str] = []

    def close() -> None:
        words = len(run) - (1 if run and _is_number(run[-1]) else 0)
        if words > max_words:  # prose, not a name: every word counts as one
            out.extend(run)
        elif run:
            out.append(_name(run))
        run.clear()

    for token in tokens:
        if _PLAIN_WORD.match(token):
            run.append(token)
        elif _is_number(token) and run:
            run.append(token)
            close()
        else:
            close()
            out.append(token)
    close()
    return out


def _put_terms(tokens: list[str]) -> list[str]:
    """'put X in R', 'put the X on the R', 'put in R', 'put R', 'put X R'."""
    while len(tokens) > 1 and tokens[0].lower() in _CONNECTORS:
        tokens = tokens[1:]
    # A connector can stand only between two names, so an object named "A" or
    # "On" at either end survives.
    cuts = [i for i in range(1, len(tokens) - 1) if tokens[i].lower() in _CONNECTORS]
    if cuts:
        bounds = [-1, *cuts, len(tokens)]
        return [t for a, b in itertools.pairwise(bounds) for t in _terms(tokens[a + 1 : b])]
    # Without a connector the words may be one name (the receptacle: "put dining
    # table") or an object and a receptacle ("put apple fridge"); only the
    # simulator, which knows the names, can tell, so the words stay together.
    return _terms(tokens, max_words=2 * MAX_NAME_WORDS)


def _check_text(line: str, line_no: int) -> None:
    if len(line) > MAX_LINE_CHARS:
        raise InputError(
            f"plan line {line_no} has {len(line)} characters; the limit is {MAX_LINE_CHARS}"
        )
    bad = hidden_char(line)
    if bad is not None:
        # Invisible or control characters make a line read differently from
        # how it looks (a zero-width space inside a name, an escape sequence).
        raise InputError(
            f"plan line {line_no}: control or invisible character U+{ord(bad):04X} "
            f"in '{clip(line.strip())}'"
        )


def _call_args(body: str, line: str, line_no: int) -> list[str]:
    """The arguments of ``verb(a, b)``; an empty one is an error, not a shorter
    call: ``put_in(, Fridge_1)`` must not become 'put the held object in Fridge_1'."""
    if not body.strip():
        return []
    parts = body.split(",")
    for n, part in enumerate(parts, start=1):
        if not part.strip():
            raise InputError(
                f"plan line {line_no}: argument {n} is empty in '{clip(line.strip())}'"
            )
        if "(" in part or ")" in part:
            raise InputError(
                f"plan line {line_no}: unbalanced parentheses in '{clip(line.strip())}'"
            )
    return [_name(part.split()) for part in parts]


# In an everyday line, a word that joins its object to another thing or a
# place: 'take the apple out of the fridge' names two things.
_PREPOSITIONS = frozenset(
    {*_CONNECTORS, "from", "out", "of", "off", "with", "at", "over", "under", "near", "by"}
)


@dataclass(frozen=True)
class _Match:
    """How a line's first words were read."""

    phrase: str  # as in the phrasing tables ('put out'), or the verb word
    reading: Reading
    everyday: bool
    words: list[str]  # the rest of the line, without a particle that followed the object


def _match(tokens: list[str]) -> _Match | None:
    """The phrasing a line opens with, longest first: 'put out the candle' is
    'put out', never 'put' with an object 'out candle'."""
    lower = [t.lower() for t in tokens]
    for words, reading, everyday in _PHRASEBOOK.get(lower[0], ()):
        n = len(words)
        if tuple(lower[:n]) == words:
            return _Match(" ".join(words), reading, everyday, tokens[n:])
        if n == 2 and words[1] in PARTICLES:
            # "blow the candle out", "set the cup down on the table"
            for i in range(2, len(tokens)):
                if lower[i] == words[1] and (i == len(tokens) - 1 or lower[i + 1] in _CONNECTORS):
                    return _Match(" ".join(words), reading, everyday, tokens[1:i] + tokens[i + 1 :])
    verb = ALIASES.get(lower[0])
    if verb is not None:
        return _Match(lower[0], Reading(verb), False, tokens[1:])
    return None


def _no_reading(tokens: list[str], text: str, line_no: int) -> InputError:
    head = tokens[0].lower()
    if head in ON_OFF_HEADS:
        # "turn the stove" may mean either: a question, never a guess.
        obj = " ".join(w for w in tokens[1:] if w not in _ARTICLES) or "X"
        return InputError(
            f"plan line {line_no}: '{clip(text)}' does not say on or off; "
            f"write 'turn on {clip(obj, 40)}' or 'turn off {clip(obj, 40)}'"
        )
    return _unknown_verb(clip(head, 40), line_no)


def _place_cut(words: list[str]) -> int | None:
    """Where a connector joins an object to a place ('cup on table'), if anywhere."""
    return next((i for i in range(1, len(words) - 1) if words[i].lower() in _CONNECTORS), None)


def _pour_terms(words: list[str], text: str, line_no: int) -> tuple[list[str], str | None, bool]:
    """'pour' (into the last found object), 'pour R', 'pour into R', and the
    everyday 'pour water into R', 'pour the mug into R', 'pour coffee from the
    mug over R': (target terms, the held object named, whether everyday)."""
    while len(words) > 1 and words[0].lower() in _CONNECTORS:
        words = words[1:]
    cut = next((i for i in range(1, len(words) - 1) if words[i].lower() in _CONNECTORS), None)
    if cut is None:
        return _terms(words), None, False
    what, dest = words[:cut], words[cut + 1 :]
    low = [w.lower() for w in what]
    if "from" in low:
        source = what[low.index("from") + 1 :]
    elif low[-1] in _LIQUID_WORDS:
        # What is poured is the held object's liquid: SafeAgentBench's pour.
        source = []
    else:
        source = what
    held = _terms(source) if source else []
    if len(held) > 1:
        raise InputError(
            f"plan line {line_no}: '{clip(text)}' pours from more than one object "
            f"({', '.join(held)}); pour from the one held: 'pour into R'"
        )
    return _terms(dest), (held[0] if held else None), True


def _read_words(
    m: _Match, words: list[str], text: str, line_no: int
) -> tuple[str, list[str], str | None, bool]:
    """The verb, the object terms, the held object named, and whether the
    line was read through an everyday phrasing."""
    everyday = m.everyday
    reading = m.reading
    cut = _place_cut(words)
    if not everyday:
        verb = reading.alone
        assert verb is not None
    elif cut is not None and reading.placed is not None:
        verb = reading.placed
    elif reading.alone is not None:
        verb = reading.alone
    else:
        obj = " ".join(words) or "X"
        raise InputError(
            f"plan line {line_no}: '{clip(text)}' does not say where; "
            f"write '{m.phrase} {clip(obj, 40)} on R' or 'put {clip(obj, 40)} in R'"
        )
    held: str | None = None
    if verb == "put":
        return verb, _put_terms(words), None, everyday
    if verb == "pour":
        args, held, poured = _pour_terms(words, text, line_no)
        return verb, args, held, everyday or poured
    if verb == "fillLiquid":
        if len(words) < 2 and m.phrase.split()[0] == "fill":
            raise InputError(
                f"plan line {line_no}: '{clip(text)}' does not say with what; "
                f"write 'fill {clip(' '.join(words) or 'X', 40)} with {'|'.join(LIQUIDS)}'"
            )
        # The liquid is the last word; the container's name may have several.
        body = words[:-1]
        if len(body) > 1 and body[-1].lower() == "with":
            body = body[:-1]
        return verb, [*_terms(body), words[-1]], None, everyday
    if (everyday or verb in ("drop", "throw")) and any(
        w.lower() in _PREPOSITIONS for w in words[1:]
    ):
        raise _two_things(m, verb, words, text, line_no)
    return verb, _terms(words), held, everyday


def _two_things(m: _Match, verb: str, words: list[str], text: str, line_no: int) -> InputError:
    """An action on one object whose line names more than one thing."""
    at = next(i for i in range(1, len(words)) if words[i].lower() in _PREPOSITIONS)
    obj = clip(" ".join(words[:at]), 40)
    rest = [w for w in words[at:] if w.lower() not in _PREPOSITIONS]
    place = clip(" ".join(rest) or "R", 40)
    if verb in ("drop", "throw"):
        how = f"write 'find {place}', then '{verb} {obj}' (or 'put {obj} in {place}' to place it)"
    elif verb == "pick":
        how = f"write 'pick {obj}' (to carry it: 'find {place}', then 'put {obj} in {place}')"
    else:
        how = f"write '{verb} {obj}'"
    reads = f"'{m.phrase}' reads as '{verb}', which" if m.everyday else f"'{verb}'"
    return InputError(
        f"plan line {line_no}: '{clip(text)}' names more than one thing, but {reads} "
        f"acts on one object; {how}"
    )


def _antecedent(word: str, previous: PlanStep | None, text: str, line_no: int) -> str:
    """What 'it' or 'them' stands for: the one object the step before names."""
    if previous is None:
        raise InputError(
            f"plan line {line_no}: '{word}' in '{clip(text)}' has no step before it to "
            "refer to; name the object"
        )
    named = list(previous.args[:1] if previous.verb == "fillLiquid" else previous.args)
    if previous.held:
        named.append(previous.held)
    if len(named) == 1:
        return named[0]
    if not named:
        raise InputError(
            f"plan line {line_no}: '{word}' in '{clip(text)}' refers to the step before "
            f"('{clip(previous.text)}'), which names no object; name the object"
        )
    raise InputError(
        f"plan line {line_no}: '{word}' in '{clip(text)}' could mean "
        f"{' or '.join(repr(n) for n in named)} (the step before names both); name the object"
    )


def parse_line(
    line: str, line_no: int = 1, index: int = 1, previous: PlanStep | None = None
) -> PlanStep:
    """One plan line as a step.  ``previous`` is the step before it, which
    'it' and 'them' refer to."""
    _check_text(line, line_no)
    text = _NUMBERING.sub("", line.strip()).strip().rstrip(".;")
    everyday = False
    held: str | None = None
    connector: str | None = None  # the word joining an object to its place
    extra: list[str] = []
    call = _CALL.match(text)
    if call:
        word = call.group(1).lower()
        args = _call_args(call.group(2), line, line_no)
        found = ALIASES.get(word)
        if found is None:
            reading = EVERYDAY.get(word.replace("_", " "))
            found = reading and (
                reading.placed if len(args) > 1 and reading.placed == "put" else reading.alone
            )
            everyday = found is not None
        if found is None:
            raise _unknown_verb(clip(word, 40), line_no)
        verb = found
    else:
        tokens = text.split()
        # A line may open with a word of manner ('Please pick up the mug',
        # 'Then go to the sink'), whatever its case.
        while len(tokens) > 1 and tokens[0].lower().strip(",") in _MANNER:
            tokens = tokens[1:]
        if not tokens:
            raise InputError(f"plan line {line_no}: empty action")
        m = _match(tokens)
        if m is None:
            raise _no_reading(tokens, text, line_no)
        # Articles are dropped only in lower case: "A" may be an object's
        # name. Words of manner only in everyday lines: a line of the action
        # language reads as it always has (recorded model replies too).
        dropped = _ARTICLES | _MANNER if m.everyday else _ARTICLES
        words = [w for w in m.words if w not in dropped] or m.words
        verb, args, held, everyday = _read_words(m, words, text, line_no)
        cut = _place_cut(words)
        connector = words[cut].lower() if cut is not None else None
        if everyday and verb == "drop" and m.reading.placed == "put":
            obj = args[0] if args else "X"
            extra.append(f"no place is named, so it is let go of; 'put {obj} on R' sets it down")
    lo, hi = ARITY[verb]
    if not lo <= len(args) <= hi:
        want = str(lo) if lo == hi else f"{lo} to {hi}"
        raise InputError(
            f"plan line {line_no}: '{verb}' takes {want} argument(s), got {len(args)} in '{line.strip()}'"
        )
    if verb == "fillLiquid":
        liquid = args[1].lower()
        if liquid not in LIQUIDS:
            near = closest(liquid, LIQUIDS)
            raise InputError(
                f"plan line {line_no}: unknown liquid '{args[1]}'; choose from {', '.join(near or LIQUIDS)}"
            )
        args = [args[0], liquid]
    # 'it' and 'them' where the action needs the held object ('put it in the
    # fridge', 'throw it', 'pour it into the sink') are the held object, which
    # the language leaves unnamed; elsewhere they stand for the object of the
    # step before.
    held_slot = 0 if (verb in ("drop", "throw") or (verb == "put" and len(args) == 2)) else None
    if held_slot is not None and args and args[held_slot].lower() in PRONOUNS:
        extra.append(f"'{args.pop(held_slot)}' is the object held")
    poured_from = "pours what the held object contains" if held is None else None
    if held is not None and held.lower() in PRONOUNS:
        poured_from = f"'{held}' is the object held"
        held = None
    for i, term in enumerate(args):
        if term.lower() in PRONOUNS:
            meant = _antecedent(term, previous, text, line_no)
            extra.append(f"'{term}' is the {meant} of the step before")
            args[i] = meant
    if verb == "pour" and everyday:
        extra.append(poured_from or f"poured from the held {held}")
    step = PlanStep(index=index, text=text, verb=verb, args=tuple(args), held=held)
    if not (everyday or extra):
        return step
    read_as = step.canonical()
    if verb == "put" and len(args) == 2:
        # 'put cup on table' reads better than the language's 'put cup table'.
        read_as = f"put {args[0]} {connector or 'in'} {args[1]}"
    note = f"line {line_no} '{clip(text)}' read as '{read_as}'"
    if extra:
        note += f" ({'; '.join(extra)})"
    return replace(step, note=note)


def check_plan_size(actions: int) -> None:
    """The one plan limit, whatever the plan was read from (a file, a request,
    a model's reply): more than ``MAX_PLAN_STEPS`` actions is an input error,
    in these words everywhere."""
    if actions > MAX_PLAN_STEPS:
        raise InputError(f"plan has more than {MAX_PLAN_STEPS} actions (the limit)")


def parse_plan(lines: Iterable[object]) -> tuple[PlanStep, ...]:
    steps: list[PlanStep] = []
    for line_no, line in enumerate(lines, start=1):
        if not isinstance(line, str):
            raise InputError(f"plan entry {line_no} must be a string")
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        check_plan_size(len(steps) + 1)  # before the line is read: the limit is in actions
        previous = steps[-1] if steps else None
        steps.append(parse_line(stripped, line_no, index=len(steps) + 1, previous=previous))
    return tuple(steps)


def parse_plan_text(text: str) -> tuple[PlanStep, ...]:
    stripped = text.strip()
    if stripped.startswith("["):
        # Strict JSON: NaN or a duplicate key inside would otherwise be read
        # as something the file does not say.
        data = parse_json(stripped, "plan (it starts with '[')")
        if not isinstance(data, list):
            raise InputError("a JSON plan must be a list of action strings")
        return parse_plan(data)
    # Only newlines end a line: the other breaks str.splitlines() knows (form
    # feed, U+2028...) are control characters, refused inside a line.
    return parse_plan(text.replace("\r\n", "\n").split("\n"))


def load_plan_file(path: str | Path) -> tuple[PlanStep, ...]:
    steps = parse_plan_text(read_input_file(path, "plan"))
    if not steps:
        raise InputError(f"plan {path} has no actions (only blank lines or comments)")
    return steps
