"""The words of the plan language: its verbs, the action class and arity of
each, the spellings of a verb, the everyday phrasings read as one, and the
state words that describe an object ("the lit candle").

These tables are the language; :mod:`virf.world.plan` reads lines with them,
the simulator chooses instances by the state words, and docs/planner.md
shows :data:`EVERYDAY` (a test checks the page against it).
"""

from __future__ import annotations

from typing import NamedTuple

VERBS = (
    "find",
    "pick",
    "put",
    "open",
    "close",
    "turn_on",
    "turn_off",
    "slice",
    "break",
    "cook",
    "dirty",
    "clean",
    "fillLiquid",
    "emptyLiquid",
    "pour",
    "drop",
    "throw",
)
LIQUIDS = ("water", "coffee", "wine")
ACTION_CLASS = {
    "find": "FindAction",
    "pick": "PickAction",
    "put": "PutAction",
    "open": "OpenAction",
    "close": "CloseAction",
    "turn_on": "ToggleOnAction",
    "turn_off": "ToggleOffAction",
    "slice": "SliceAction",
    "break": "BreakAction",
    "cook": "CookAction",
    "dirty": "DirtyAction",
    "clean": "CleanAction",
    "fillLiquid": "FillLiquidAction",
    "emptyLiquid": "EmptyLiquidAction",
    "pour": "PourAction",
    "drop": "DropAction",
    "throw": "ThrowAction",
}
# verb -> (min args, max args)
ARITY = {
    "find": (1, 1),
    "pick": (1, 1),
    "put": (1, 2),
    "open": (1, 1),
    "close": (1, 1),
    "turn_on": (1, 1),
    "turn_off": (1, 1),
    "slice": (1, 1),
    "break": (1, 1),
    "cook": (1, 1),
    "dirty": (1, 1),
    "clean": (1, 1),
    "fillLiquid": (2, 2),
    "emptyLiquid": (1, 1),
    "pour": (0, 1),
    # The object named is the one held: "throw AlarmClock" throws what the
    # hand holds only if that is the AlarmClock.
    "drop": (0, 1),
    "throw": (0, 1),
}
# Every one-word spelling of a verb (lower case), with the verb it spells.
ALIASES = {
    "find": "find",
    "navigate": "find",
    "pick": "pick",
    "pickup": "pick",
    "pick_up": "pick",
    "put": "put",
    "put_in": "put",
    "put_on": "put",
    "place": "put",
    "open": "open",
    "close": "close",
    "turn_on": "turn_on",
    "turnon": "turn_on",
    "toggle_on": "turn_on",
    "toggleon": "turn_on",
    "turn_off": "turn_off",
    "turnoff": "turn_off",
    "toggle_off": "turn_off",
    "toggleoff": "turn_off",
    "slice": "slice",
    "break": "break",
    "cook": "cook",
    "dirty": "dirty",
    "clean": "clean",
    "fillliquid": "fillLiquid",
    "fill_liquid": "fillLiquid",
    "fill": "fillLiquid",
    "emptyliquid": "emptyLiquid",
    "empty_liquid": "emptyLiquid",
    "pour": "pour",
    "drop": "drop",
    "throw": "throw",
}


class Reading(NamedTuple):
    """The action an everyday phrasing means: ``alone`` when the line names
    only the object, ``placed`` when a place follows it ('set the cup down'
    lets go of the cup, 'set the cup down on the table' puts it there).
    None: the phrasing cannot be read that way, and the line is an error."""

    alone: str | None
    placed: str | None = None


# Everyday phrasings of people and LLMs, and the action of the language each
# one is read as; a line that uses one gets a note in the report saying how it
# was read.  This one table drives the reader, its error messages and the
# table in docs/planner.md (a test checks the page against it).  A phrase of
# several words is matched before any shorter one it starts with ("put out
# the candle" is never 'put' into an "out candle"); a last word that is a
# particle (on, off, up, down, out) may also follow the object ("blow the
# candle out").
EVERYDAY: dict[str, Reading] = {
    # find: SafeAgentBench's find takes the robot to the object.
    "go to": Reading("find"),
    "walk to": Reading("find"),
    "move to": Reading("find"),
    "head to": Reading("find"),
    "get to": Reading("find"),
    "navigate to": Reading("find"),
    "approach": Reading("find"),
    "locate": Reading("find"),
    "look for": Reading("find"),
    "search for": Reading("find"),
    # pick
    "grab": Reading("pick"),
    "take": Reading("pick"),
    "get": Reading("pick"),
    "lift": Reading("pick"),
    # put: the held object into or onto a place the line names.  With "down"
    # and no place ("put down the cup") the robot only lets go of it, which is
    # the language's drop: AI2-THOR drops it where it stands, and a fragile
    # object breaks.  That is what gets verified, rather than a gentle placing
    # on a surface the line does not name.  Without "down", a phrasing that
    # names no place ("set the cup") is an error: there is nothing to read.
    "set": Reading(None, "put"),
    "lay": Reading(None, "put"),
    "insert": Reading(None, "put"),
    "put down": Reading("drop", "put"),
    "set down": Reading("drop", "put"),
    "lay down": Reading("drop", "put"),
    "place down": Reading("drop", "put"),
    # drop
    "release": Reading("drop"),
    "let go of": Reading("drop"),
    "let go": Reading("drop"),
    # throw
    "toss": Reading("throw"),
    "hurl": Reading("throw"),
    "fling": Reading("throw"),
    # close
    "shut": Reading("close"),
    # turn_on: a candle or a burner is lit by switching it on in the language.
    "light": Reading("turn_on"),
    "light up": Reading("turn_on"),
    "ignite": Reading("turn_on"),
    "start": Reading("turn_on"),
    "activate": Reading("turn_on"),
    "power on": Reading("turn_on"),
    # turn_off: a flame is put out by switching it off in the language.
    "put out": Reading("turn_off"),
    "blow out": Reading("turn_off"),
    "snuff out": Reading("turn_off"),
    "extinguish": Reading("turn_off"),
    "stop": Reading("turn_off"),
    "deactivate": Reading("turn_off"),
    "power off": Reading("turn_off"),
    "shut off": Reading("turn_off"),
    "shut down": Reading("turn_off"),
    # slice
    "cut": Reading("slice"),
    "cut up": Reading("slice"),
    "chop": Reading("slice"),
    "chop up": Reading("slice"),
    "dice": Reading("slice"),
    # break
    "smash": Reading("break"),
    "shatter": Reading("break"),
    "crack": Reading("break"),
    # cook: SafeAgentBench's cook says neither how nor with what.  "microwave
    # the bowl" is read as cook, so no microwave is simulated: a plan whose
    # appliance should be checked must put the object in it and switch it on.
    "heat": Reading("cook"),
    "heat up": Reading("cook"),
    "warm": Reading("cook"),
    "warm up": Reading("cook"),
    "microwave": Reading("cook"),
    "fry": Reading("cook"),
    "boil": Reading("cook"),
    "bake": Reading("cook"),
    "toast": Reading("cook"),
    # dirty
    "soil": Reading("dirty"),
    # clean
    "wash": Reading("clean"),
    "rinse": Reading("clean"),
    "wipe": Reading("clean"),
    "scrub": Reading("clean"),
    # fillLiquid ("fill X with water" is the language's own)
    "fill up": Reading("fillLiquid"),
    # emptyLiquid; "empty the mug into the sink" pours the held mug there.
    "empty": Reading("emptyLiquid", "pour"),
    "empty out": Reading("emptyLiquid", "pour"),
    "drain": Reading("emptyLiquid"),
}
# Multi-word spellings of the action language itself: read without a note.
LANGUAGE_PHRASES = {
    "turn on": "turn_on",
    "turn off": "turn_off",
    "toggle on": "turn_on",
    "toggle off": "turn_off",
    "switch on": "turn_on",
    "switch off": "turn_off",
    "pick up": "pick",
}
# Words that switch a device without saying on or off: "turn the stove" is
# a question, not a guess.
ON_OFF_HEADS = ("turn", "toggle", "switch", "power")
# A phrase's last word that may follow the object ("turn the lamp off").
PARTICLES = frozenset({"on", "off", "up", "down", "out"})
# Leading words that describe an object's current state ("the lit candle"):
# not part of its name.  The simulator uses them to choose among instances.
STATE_ADJECTIVES: dict[str, str] = {
    "lit": "OnState",
    "burning": "OnState",
    "running": "OnState",
    "on": "OnState",
    "unlit": "OffState",
    "off": "OffState",
    "open": "OpenState",
    "closed": "ClosedState",
    "hot": "HotState",
    "cold": "ColdState",
    "dirty": "DirtyState",
    "clean": "CleanState",
    "full": "FilledWithLiquidState",
    "filled": "FilledWithLiquidState",
    "empty": "EmptyState",
    "sliced": "SlicedState",
    "broken": "BrokenState",
    "wet": "WetState",
}
