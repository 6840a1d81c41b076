"""The objects an instruction names, to hold a small model's plan to them.

A 135M-parameter model given every line a kitchen allows (some 2,000) writes
plans about whatever it happens to start with; given the lines about the
apple and the fridge, it writes about the apple and the fridge.
:func:`named_objects` reads the instruction's words with the plan reader's own
resolution (:meth:`virf.world.simulator.Simulator.resolve_term`: instance
names, types and their synonyms and subclasses, plurals), so "the eggs", "the
Egg" and "the CounterTop" name what a plan line saying them would.

Focus only narrows what the model may write; it never decides safety.  The
tutor verifies every plan against the whole scene, and the objects of a
checked correction join the focus (:meth:`Focus.widen`), so a correction that
turns off a burner the instruction never mentioned can still be written.  An
instruction that names nothing in the scene leaves the model every object.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Final

from virf.errors import InputError
from virf.names import name_words
from virf.ontology.tbox import Vocabulary
from virf.planner.constraint import PlanConstraint, plan_constraint
from virf.planner.stepwise import Sandbox
from virf.schema import FactKind
from virf.world.plan import parse_line, singular_forms
from virf.world.scene import Scene
from virf.world.simulator import Simulator

# The longest name read in one piece: "stove knob 2" is three words.
MAX_WORDS: Final = 3
_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
# A word shorter than this is a preposition or a pronoun far more often than
# a part of an object's name.
MIN_PART: Final = 4
# Words of names that say where, not what ('CounterTop', 'TableTop').
_NOT_PARTS: Final = frozenset({"top", "side", "front", "back", "bottom", "small", "large"})
_NUMBER = re.compile(r"_?\d+$")


def named_objects(instruction: str, scene: Scene, vocab: Vocabulary) -> frozenset[str]:
    """The scene's objects the instruction names, and those a fact of the
    scene links them to.

    The words are read longest reading first ('the stove knob' names the
    knob, not every stove part); a word naming a type names all its instances
    in the scene.  A word that names nothing itself names the objects one of
    whose name's words it is ('stove' names StoveBurner_1 and StoveKnob_1).
    An object the scene relates to a named one (the knob that controls the
    named burner, the counter the named kettle stands on) joins them: a task
    is done with the things around what it names."""
    sim = Simulator(vocab)
    state = sim.initial(scene)
    words = _WORD.findall(instruction)
    found: set[str] = set()
    i = 0
    while i < len(words):
        for n in range(min(MAX_WORDS, len(words) - i), 0, -1):
            got = sim.resolve_term(state, " ".join(words[i : i + n]))
            if got is not None:
                found.update((got,) if isinstance(got, str) else got)
                i += n
                break
        else:
            found.update(_part_of_name(words[i], scene))
            i += 1
    found.discard(scene.agent)
    linked = {
        other
        for fact in scene.facts
        if fact.kind is FactKind.OBJECT and fact.object in scene.objects
        for end, other in ((fact.subject, fact.object), (fact.object, fact.subject))
        if end in found
    }
    return frozenset((found | linked) - {scene.agent})


def _part_of_name(word: str, scene: Scene) -> set[str]:
    """The objects whose name (its number aside) has ``word`` as one of its
    words, in any singular reading; short words ('on', 'it', 'top') never."""
    if len(word) < MIN_PART:
        return set()
    forms = {word.lower(), *(f.lower() for f in singular_forms(word))}
    return {
        ind
        for ind in scene.order
        if forms & set(name_words(_NUMBER.sub("", ind)).split()) - _NOT_PARTS
    }


@dataclass(frozen=True)
class Focus:
    """The constraint of one task: the whole scene's lines, narrowed to the
    objects in ``objects`` when there are any."""

    whole: PlanConstraint
    objects: frozenset[str]

    @classmethod
    def of(
        cls,
        instruction: str,
        scene: Scene,
        vocab: Vocabulary,
        judge: Callable[[tuple[str, ...]], bool] | None = None,
    ) -> Focus:
        """The focus of ``instruction``; ``judge`` is the tutor's word on a
        plan's lines as they are written (:class:`virf.planner.stepwise.Sandbox`)."""
        whole = plan_constraint(scene, vocab).within(Sandbox(scene, vocab, judge))
        return cls(whole, named_objects(instruction, scene, vocab))

    def constraint(self) -> PlanConstraint:
        return self.whole.narrowed(self.objects) if self.objects else self.whole

    def widen(self, lines: Iterable[str]) -> Focus:
        """This focus with the objects the plan ``lines`` name added (the
        lines of the checked corrections offered to the model)."""
        if not self.objects:
            return self
        known = {name for _, names in self.whole.takes for name in names}
        extra: set[str] = set()
        for n, line in enumerate(lines, 1):
            try:
                step = parse_line(line, n, n, None)
            except InputError:
                continue  # not a line at all: it names nothing to allow
            extra.update(a for a in step.args if a in known)
        return Focus(self.whole, self.objects | extra)
