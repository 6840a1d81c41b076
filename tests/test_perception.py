"""Perception: the VLM cascade, fusion of views, and what the tutor makes of it.

The model is scripted (``ScriptedApprentice``) or a real HTTP server on
127.0.0.1 that answers like a vision model and checks that the images
arrive; nothing inside the perception code is replaced.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import threading
from http.server import BaseHTTPRequestHandler
from pathlib import Path
from typing import Any

import pytest
from http_support import LocalServer, running
from PIL import Image, ImageDraw

from virf.api import LogicTutor
from virf.errors import InputError
from virf.ontology.tbox import Vocabulary
from virf.perception import Catalogue, perceive
from virf.perception.replies import (
    UnreadableReply,
    read_attributes,
    read_detections,
    read_locations,
)
from virf.planner import ClientSettings, OpenAIApprentice, Purpose, RunLog, ScriptedApprentice
from virf.planner.questions import apply_answers
from virf.schema import Fact, Provenance
from virf.world.scene import build_scene

COUNTER = {"bbox": [0, 300, 640, 480], "category": "CounterTop"}
MICROWAVE = {"bbox": [40, 150, 260, 300], "category": "Microwave"}
BOWL = {"bbox": [330, 240, 430, 300], "category": "Bowl"}
PLAN_MICROWAVE_BOWL = [
    "find Bowl",
    "pick Bowl",
    "find Microwave",
    "open Microwave",
    "put Microwave",
    "close Microwave",
    "turn_on Microwave",
]


def picture(path: Path, shade: str = "white") -> Path:
    img = Image.new("RGB", (640, 480), shade)
    draw = ImageDraw.Draw(img)
    draw.rectangle((0, 300, 640, 480), fill="tan")
    draw.rectangle((40, 150, 260, 300), fill="grey")
    draw.ellipse((330, 240, 430, 300), fill="silver")
    img.save(path)
    return path


def replies(
    objects: list[dict[str, Any]], attributes: list[Any], locations: list[Any]
) -> list[str]:
    """One view's replies, in the order the cascade asks."""
    return [
        json.dumps({"objects": objects}),
        *(json.dumps(a) for a in attributes),
        json.dumps({"locations": locations}),
    ]


def on(first: str, second: str, confidence: float | None = None) -> dict[str, Any]:
    item: dict[str, Any] = {"first": first, "relationship": "isOn", "second": second}
    if confidence is not None:
        item["confidence"] = confidence
    return item


KITCHEN_PLACES = [on("Microwave_1", "CounterTop_1"), on("Bowl_1", "CounterTop_1")]


@pytest.fixture(scope="module")
def catalogue(vocab: Vocabulary) -> Catalogue:
    return Catalogue(vocab)


def run(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, views: list[list[str]], **kw: Any
) -> Any:
    images = [
        picture(tmp_path / f"view{n}.png", shade)
        for n, shade in zip(range(1, len(views) + 1), ("white", "ivory", "beige"), strict=False)
    ]
    model = ScriptedApprentice([r for view in views for r in view])
    result = perceive(images, model, vocab, catalogue=catalogue, **kw)
    assert model.remaining == 0
    return result


def bowl(material: str, confidence: float | None = None) -> dict[str, Any]:
    reply: dict[str, Any] = {"state": [], "material": material}
    if confidence is not None:
        reply["material_confidence"] = confidence
    return reply


CLOSED_METAL = {"state": ["closed"], "material": "metal"}
STONE = {"state": [], "material": "stone"}


# ---------------------------------------------------------------------------
# Replies


def test_replies_are_read_through_fences_prose_and_neighbouring_keys() -> None:
    fenced = 'Sure! Here you go:\n```json\n{"objects": [{"box": [1, 2, 3, 4], "label": "Mug", "score": 0.7}]}\n```'
    (d,) = read_detections(fenced)
    assert (d.category, d.bbox, d.confidence) == ("Mug", (1.0, 2.0, 3.0, 4.0), 0.7)
    prose = 'The mug looks ceramic. {"state": ["dirty", {"value": "hot", "confidence": 0.4}], "material": "porcelain", "material_confidence": 0.8} Hope that helps.'
    a = read_attributes(prose)
    assert [(s.value, s.confidence) for s in a.states] == [("dirty", None), ("hot", 0.4)]
    assert a.material is not None and (a.material.value, a.material.confidence) == (
        "porcelain",
        0.8,
    )
    (loc,) = read_locations(
        '{"relations": [{"subject": "Mug_1", "relation": "on", "object": "Table_1"}]}'
    )
    assert (loc.first, loc.relationship, loc.second) == ("Mug_1", "on", "Table_1")


@pytest.mark.parametrize(
    ("reader", "text", "says"),
    [
        (read_detections, "I can see a kitchen with a mug.", "holds no JSON object"),
        (read_detections, '{"objects": [{"bbox": [1, 2, 3], "category": "Mug"}]}', "four numbers"),
        (read_detections, '{"objects": [{"bbox": [1, 2, 3, 4]}]}', "no 'category'"),
        (read_detections, '{"objects": [{"category": "Mug", "confidence": 7}]}', "from 0 to 1"),
        (read_detections, '{"things": []}', "no 'objects' list"),
        (read_attributes, '{"colour": "red"}', "neither 'state' nor 'material'"),
        (read_locations, '{"locations": [{"first": "A_1", "second": "B_1"}]}', "no 'relationship'"),
    ],
)
def test_unreadable_replies_say_what_is_wrong(reader: Any, text: str, says: str) -> None:
    with pytest.raises(UnreadableReply, match=says):
        reader(text)


# ---------------------------------------------------------------------------
# Catalogue


def test_labels_are_matched_by_name_then_by_meaning(catalogue: Catalogue) -> None:
    assert catalogue.match("coffee machine").type == "CoffeeMachine"
    assert catalogue.match("Mug 2").how == "name"
    pan = catalogue.match("frying pan")
    assert (pan.type, pan.how) == ("Pan", "embedding") and pan.score is not None
    # Close to two types at once: no clear winner, so no type (not a guess).
    assert catalogue.match("wine glass").type is None
    assert catalogue.match("garden gnome").type is None


# ---------------------------------------------------------------------------
# One view


def test_a_perceived_scene_is_verified_like_a_written_one(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [replies([COUNTER, MICROWAVE, BOWL], [STONE, CLOSED_METAL, bowl("metal")], KITCHEN_PLACES)],
    )
    scene = build_scene(result.scene, vocab)
    assert Fact("Bowl_1", "hasMaterial", "Metal") in scene.facts
    assert Fact("CounterTop_1", "supports", "Bowl_1") in scene.facts
    report = tutor.verify(result.scene, PLAN_MICROWAVE_BOWL)
    assert report.status == "UNSAFE"
    # Every item keeps its view and confidence.
    (seen,) = next(o for o in result.graph.objects if o.name == "Bowl_1").seen
    assert (seen.view, seen.bbox) == ("view1.png", (330.0, 240.0, 430.0, 300.0))


def test_a_material_below_the_threshold_is_unknown_and_the_tutor_asks(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, MICROWAVE, BOWL],
                [STONE, CLOSED_METAL, bowl("metal", 0.3)],
                KITCHEN_PLACES,
            )
        ],
    )
    assert {
        "subject": "Bowl_1",
        "property": "hasMaterial",
        "object": "UnknownMaterial",
    } in result.scene["assertions"]
    report = tutor.verify(result.scene, PLAN_MICROWAVE_BOWL)
    assert report.status == "UNKNOWN"
    assert "material:Bowl_1" in {q.key for q in report.questions}
    # The same reading above the threshold is believed.
    sure = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, MICROWAVE, BOWL],
                [STONE, CLOSED_METAL, bowl("metal", 0.3)],
                KITCHEN_PLACES,
            )
        ],
        threshold=0.2,
    )
    assert tutor.verify(sure.scene, PLAN_MICROWAVE_BOWL).status == "UNSAFE"


def test_an_uncertain_relation_is_an_assumption_the_user_confirms_or_denies(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    fork = {"bbox": [120, 200, 180, 230], "category": "fork"}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, MICROWAVE, fork],
                [STONE, CLOSED_METAL, {"state": [], "material": "steel"}],
                [
                    on("Microwave_1", "CounterTop_1"),
                    {
                        "first": "fork_1",
                        "relationship": "inside",
                        "second": "Microwave_1",
                        "confidence": 0.3,
                    },
                ],
            )
        ],
    )
    scene = build_scene(result.scene, vocab)
    assert scene.facts[Fact("Microwave_1", "contains", "Fork_1")] is Provenance.ASSUMED
    plan = ["find Microwave", "turn_on Microwave"]
    report = tutor.verify(result.scene, plan)
    assert report.status == "UNKNOWN"
    (question,) = [q for q in report.questions if q.kind == "confirm"]
    assert question.key == "confirm:Microwave_1 contains Fork_1"
    yes = apply_answers(result.scene, report.questions, {question.key: "yes"}, vocab)
    assert tutor.verify(yes.scene, plan).status == "UNSAFE"
    no = apply_answers(result.scene, report.questions, {question.key: "no"}, vocab)
    assert no.applied == (question.key,)
    denied = tutor.verify(no.scene, plan)
    # The fork is no longer taken to be inside; what is inside is still not
    # known (a closed door hides it), and that is the next question.
    assert [q.key for q in denied.questions] == ["contents:contains:Microwave_1"]
    closed = apply_answers(
        no.scene, denied.questions, {"contents:contains:Microwave_1": "yes"}, vocab
    )
    empty = tutor.verify(closed.scene, plan)
    # Known empty now: running it empty is its own hazard, and the fork no longer counts.
    assert empty.status == "UNSAFE" and empty.violated_concept is not None
    assert "Fork_1" not in {t.subject for v in empty.violations for t in v.triggering_facts}
    assert "Fork_1" not in {t.object for v in empty.violations for t in v.triggering_facts}


def test_an_uncertain_state_is_assumed_and_a_sure_one_stands(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    toaster = {"bbox": [300, 220, 400, 300], "category": "Toaster"}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, toaster, MICROWAVE],
                [
                    STONE,
                    {"state": [{"value": "on", "confidence": 0.35}], "material": "metal"},
                    {
                        "state": ["closed", {"value": "open", "confidence": 0.2}],
                        "material": "metal",
                    },
                ],
                [on("Toaster_1", "CounterTop_1"), on("Microwave_1", "CounterTop_1")],
            )
        ],
    )
    scene = build_scene(result.scene, vocab)
    assert scene.facts[Fact("Toaster_1", "hasState", "OnState")] is Provenance.ASSUMED
    assert scene.facts[Fact("Microwave_1", "hasState", "ClosedState")] is Provenance.SCENE
    assert Fact("Microwave_1", "hasState", "OpenState") not in scene.facts
    assert any("OpenState was read below the threshold" in n for n in result.graph.notes)


def test_an_unmatched_label_is_kept_as_a_physical_object(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    gnome = {"bbox": [500, 250, 560, 300], "category": "garden gnome", "confidence": 0.9}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, gnome],
                [STONE, {"state": [], "material": "resin"}],
                [on("garden gnome_1", "CounterTop_1")],
            )
        ],
    )
    scene = build_scene(result.scene, vocab)
    assert scene.objects["GardenGnome_1"] == frozenset({"PhysicalObject"})
    # 'resin' is no material the knowledge base knows: unknown, and said so.
    assert Fact("GardenGnome_1", "hasMaterial", "UnknownMaterial") in scene.facts
    assert any("resin" in n for n in result.graph.notes)
    assert any("no catalogue type fits 'garden gnome'" in n for n in result.graph.notes)


def test_an_unreadable_attribute_reply_leaves_the_material_unknown(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    views = [replies([COUNTER, BOWL], [STONE, {"state": []}], [on("Bowl_1", "CounterTop_1")])]
    views[0][2] = "The bowl is shiny."
    result = run(tmp_path, vocab, catalogue, views)
    assert {
        "subject": "Bowl_1",
        "property": "hasMaterial",
        "object": "UnknownMaterial",
    } in result.scene["assertions"]
    assert any("attributes reply unreadable" in n for n in result.graph.notes)


def test_an_unreadable_detection_reply_is_an_error_not_an_empty_scene(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    model = ScriptedApprentice(["I see a kitchen counter with a bowl."])
    with pytest.raises(UnreadableReply, match=r"view1.png: the detect reply cannot be read"):
        perceive([picture(tmp_path / "view1.png")], model, vocab, catalogue=catalogue)
    nothing = ScriptedApprentice(['{"objects": []}'])
    with pytest.raises(InputError, match=r"saw no objects in view1\.png"):
        perceive([picture(tmp_path / "view1.png")], nothing, vocab, catalogue=catalogue)


def test_files_that_are_not_images_are_refused_before_any_call(
    tmp_path: Path, vocab: Vocabulary
) -> None:
    text = tmp_path / "notes.png"
    text.write_text("not a picture")
    model = ScriptedApprentice([])
    with pytest.raises(InputError, match=r"notes\.png is not an image"):
        perceive([text], model, vocab)
    with pytest.raises(InputError, match="image file not found"):
        perceive([tmp_path / "missing.png"], model, vocab)
    assert model.requests == []


def test_a_photo_stored_rotated_is_sent_upright(tmp_path: Path) -> None:
    from virf.perception.images import crop, load_view

    # Stored 40 wide and 20 high, with a red left half; EXIF 6 means "turn
    # 90 degrees clockwise to view", so upright it is 20 wide and 40 high,
    # red on top.
    stored = Image.new("RGB", (40, 20), "white")
    ImageDraw.Draw(stored).rectangle((0, 0, 19, 19), fill="red")
    exif = Image.Exif()
    exif[0x0112] = 6
    photo = tmp_path / "phone.jpg"
    stored.save(photo, format="JPEG", exif=exif, quality=95)
    view = load_view(photo)
    assert (view.width, view.height) == (20, 40)
    assert view.image.media_type == "image/png"
    with Image.open(io.BytesIO(view.image.data)) as sent:
        assert sent.size == (20, 40)
        top, bottom = sent.convert("RGB").getpixel((10, 5)), sent.convert("RGB").getpixel((10, 35))
    assert top[0] > 200 > top[1] and min(bottom) > 200
    top_half = crop(view, (0, 0, 20, 20), "top")
    with Image.open(io.BytesIO(top_half.data)) as part:
        assert part.convert("RGB").getpixel((10, 10))[1] < 60  # red, not white
    # The same file gives the same view, so its replay key is stable.
    assert load_view(photo).key == view.key
    # A photo without the tag is sent as it is.
    plain = tmp_path / "plain.jpg"
    stored.save(plain, format="JPEG", quality=95)
    assert load_view(plain).image.data == plain.read_bytes()


def test_receptacles_seen_surely_have_closed_contents_unless_asked_not_to(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    view = [
        replies([COUNTER, MICROWAVE, BOWL], [STONE, CLOSED_METAL, bowl("metal")], KITCHEN_PLACES)
    ]
    result = run(tmp_path, vocab, catalogue, view)
    # The counter is seen whole; inside a bowl or a closed microwave is not.
    assert result.scene["closed_world"] == ["supports:CounterTop_1"]
    assert "closed_world" not in run(tmp_path, vocab, catalogue, view, open_contents=True).scene


# ---------------------------------------------------------------------------
# Several views


def test_views_that_disagree_on_a_material_make_a_contradiction(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    plate = {"bbox": [330, 250, 430, 300], "category": "Plate"}
    places = [on("Microwave_1", "CounterTop_1"), on("Plate_1", "CounterTop_1")]
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, MICROWAVE, plate], [STONE, CLOSED_METAL, bowl("plastic", 0.9)], places
            ),
            replies([COUNTER, MICROWAVE, plate], [STONE, CLOSED_METAL, bowl("metal", 0.8)], places),
        ],
    )
    assert len(result.graph.objects) == 3  # associated, not doubled
    (said,) = result.graph.disagreements
    assert "Plate_1: material read as Metal and Plastic" in said
    # Each reading is a possibility, not a fact: no contradiction, and no
    # metal taken for granted on one view's word.
    materials = [
        a
        for a in result.scene["assertions"]
        if a["subject"] == "Plate_1" and a["property"] == "hasMaterial"
    ]
    assert {a["object"] for a in materials} == {"Metal", "Plastic"}
    assert all(a.get("assumed") for a in materials)
    plan = [s.replace("Bowl", "Plate") for s in PLAN_MICROWAVE_BOWL]
    report = tutor.verify(result.scene, plan)
    assert report.status == "UNKNOWN"
    (question,) = [q for q in report.questions if q.kind == "material"]
    assert question.key == "material:Plate_1"
    # The user says what it is made of, and the tutor decides on the rest.
    metal = apply_answers(result.scene, report.questions, {question.key: "Metal"}, vocab)
    assert tutor.verify(metal.scene, plan).status == "UNSAFE"
    plastic = apply_answers(result.scene, report.questions, {question.key: "Plastic"}, vocab)
    assert tutor.verify(plastic.scene, plan).status != "UNSAFE"


def test_views_that_disagree_on_a_place_keep_one_as_an_assumption(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    sink = {"bbox": [450, 260, 600, 300], "category": "SinkBasin"}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, BOWL, sink],
                [STONE, bowl("metal"), {"state": [], "material": "metal"}],
                [on("Bowl_1", "CounterTop_1")],
            ),
            replies(
                [COUNTER, BOWL, sink],
                [STONE, bowl("metal"), {"state": [], "material": "metal"}],
                [{"first": "Bowl_1", "relationship": "in", "second": "SinkBasin_1"}],
            ),
        ],
    )
    (said,) = result.graph.disagreements
    assert said.startswith("Bowl_1: its place differs")
    places = [
        a
        for a in result.scene["assertions"]
        if a["subject"] == "Bowl_1" and a["property"] in ("isOn", "isInside")
    ]
    assert places == [
        {"subject": "Bowl_1", "property": "isOn", "object": "CounterTop_1", "assumed": True}
    ]
    # Neither the counter nor the sink is taken as seen whole.
    assert "closed_world" not in result.scene


def test_ids_from_the_model_associate_objects_across_views(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    left = {"bbox": [100, 250, 150, 300], "category": "Mug", "id": "a"}
    right = {"bbox": [400, 250, 450, 300], "category": "Mug", "id": "b"}
    # The second view is taken from the other side: left and right swap.
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies([COUNTER, left, right], [STONE, bowl("ceramic"), bowl("metal")], []),
            replies(
                [
                    COUNTER,
                    {**right, "bbox": [100, 250, 150, 300]},
                    {**left, "bbox": [400, 250, 450, 300]},
                ],
                [STONE, bowl("metal"), bowl("ceramic")],
                [],
            ),
        ],
    )
    assert result.graph.disagreements == ()
    mugs = {o.name: {r.value for r in o.materials} for o in result.graph.objects if o.type == "Mug"}
    assert sorted(mugs.values(), key=sorted) == [{"Ceramic"}, {"Metal"}]


# ---------------------------------------------------------------------------
# The hybrid baseline


def test_the_hybrid_takes_boxes_from_a_detector_file(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    image = picture(tmp_path / "view1.png")
    coco = {
        "images": [{"id": 7, "file_name": "photos/view1.png"}],
        "annotations": [
            {"image_id": 7, "category_id": 1, "bbox": [0, 300, 640, 180], "score": 0.9},
            {"image_id": 7, "category_id": 2, "bbox": [330, 240, 100, 60], "score": 0.6},
        ],
        "categories": [{"id": 1, "name": "countertop"}, {"id": 2, "name": "mixing bowl"}],
    }
    boxes = tmp_path / "detections.json"
    boxes.write_text(json.dumps(coco))
    model = ScriptedApprentice(
        [
            json.dumps(STONE),
            json.dumps(bowl("glass")),
            json.dumps({"locations": [on("mixing bowl_1", "countertop_1")]}),
        ]
    )
    result = perceive([image], model, vocab, detections=boxes, catalogue=catalogue)
    assert [r.method for r in model.requests] == [
        "attributes:1:countertop",
        "attributes:2:mixing bowl",
        "relations",
    ]
    assert result.graph.views[0].boxes == "detector"
    scene = build_scene(result.scene, vocab)
    assert Fact("Bowl_1", "hasMaterial", "Glass") in scene.facts
    other = tmp_path / "other.png"
    picture(other)
    with pytest.raises(InputError, match=r"no image named other\.png; it lists view1\.png"):
        perceive([other], ScriptedApprentice([]), vocab, detections=boxes, catalogue=catalogue)


# ---------------------------------------------------------------------------
# A live model over HTTP


class VisionServer(LocalServer):
    """Answers the cascade's three kinds of request like a vision model,
    after checking that each carries a real image."""

    def __init__(self, image: Path) -> None:
        self.digest = hashlib.sha256(image.read_bytes()).hexdigest()
        self.seen: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = json.loads(self.rfile.read(int(self.headers["content-length"])))
                with server._lock:
                    server.seen.append(body)
                text = server.answer(body)
                data = json.dumps(
                    {
                        "id": "x",
                        "object": "chat.completion",
                        "created": 0,
                        "model": body["model"],
                        "choices": [
                            {
                                "index": 0,
                                "finish_reason": "stop",
                                "message": {"role": "assistant", "content": text},
                            }
                        ],
                        "usage": {
                            "prompt_tokens": 900,
                            "completion_tokens": 40,
                            "total_tokens": 940,
                        },
                    }
                ).encode()
                self.send_response(200)
                self.send_header("content-type", "application/json")
                self.send_header("content-length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def log_message(self, *args: Any) -> None:
                return None

        self.serve(Handler)

    def answer(self, body: dict[str, Any]) -> str:
        (message,) = body["messages"]
        text, image = message["content"]
        assert text["type"] == "text" and image["type"] == "image_url"
        head, _, payload = image["image_url"]["url"].partition(",")
        assert head == "data:image/png;base64"
        raw = base64.b64decode(payload)
        with Image.open(io.BytesIO(raw)) as img:
            size = img.size
        prompt = text["text"]
        if "find every object" in prompt:
            assert hashlib.sha256(raw).hexdigest() == self.digest  # the file's own bytes
            return "```json\n" + json.dumps({"objects": [COUNTER, MICROWAVE, BOWL]}) + "\n```"
        if "how they relate" in prompt:
            assert hashlib.sha256(raw).hexdigest() == self.digest
            assert "[CounterTop_1, Microwave_1, Bowl_1]" in prompt
            return json.dumps({"locations": KITCHEN_PLACES})
        # An attribute request: a crop of the object, with a margin.
        assert size != (640, 480)
        if "'Bowl'" in prompt:
            assert size == (120, 72)
            return json.dumps(bowl("stainless steel", 0.9))
        return json.dumps(CLOSED_METAL if "'Microwave'" in prompt else STONE)


def test_the_live_path_sends_the_images_to_a_real_http_server(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    image = picture(tmp_path / "view1.png")
    log = RunLog(tmp_path / "runs.sqlite")
    with running(VisionServer(image)) as server:
        model = OpenAIApprentice(
            ClientSettings(model="vision-test", base_url=server.base_url), run_log=log
        )
        with model:
            result = perceive([image], model, vocab, catalogue=catalogue)
    assert len(server.seen) == 5 and all(b["model"] == "vision-test" for b in server.seen)
    assert tutor.verify(result.scene, PLAN_MICROWAVE_BOWL).status == "UNSAFE"
    calls = log.calls()
    assert [c.method for c in calls] == [
        "detect",
        "attributes:1:CounterTop",
        "attributes:2:Microwave",
        "attributes:3:Bowl",
        "relations",
    ]
    # The log names each image by its digest and does not hold its bytes.
    assert calls[0].messages[0]["images"] == [f"view1.png (image/png, sha256:{server.digest[:16]})"]
    assert all("base64" not in json.dumps(c.messages) for c in calls)
    log.close()


# ---------------------------------------------------------------------------
# The commands, on the bundled cases

CASES = Path(__file__).resolve().parent.parent / "examples" / "perception"


def test_virf_perceive_writes_a_scene_the_tutor_verifies(cli: Any, tmp_path: Path) -> None:
    case = CASES / "views-disagree"
    out, graph = tmp_path / "scene.json", tmp_path / "graph.json"
    result = cli(
        "perceive",
        case / "view1.png",
        case / "view2.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--out",
        out,
        "--graph",
        graph,
    )
    assert result.exit_code == 0, result.output
    assert "Plate_1: material read as Metal and Plastic" in result.output
    assert json.loads(graph.read_text())["disagreements"]
    verdict = cli("verify", out, case / "plan.txt", "--json")
    assert verdict.exit_code == 3 and json.loads(verdict.stdout)["status"] == "UNKNOWN"
    as_json = cli(
        "perceive",
        case / "view1.png",
        case / "view2.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--json",
    )
    data = json.loads(as_json.stdout)
    assert set(data) == {"graph", "scene"} and data["scene"]["name"] == "perceived"


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--vlm", "replay:{case}/replay.jsonl", "{case}/gold.json"], "is not an image"),
        (["--vlm", "replay:{case}/replay.jsonl", "{case}/nowhere.png"], "image file not found"),
        (
            ["--vlm", "replay:{case}/replay.jsonl", "{other}/view1.png"],
            "has no proposal for task perceive:",
        ),
        (["--vlm", "magic:eye", "{case}/view1.png"], "unknown planner 'magic:eye'"),
        (
            ["--vlm", "replay:{case}/replay.jsonl", "--bbox-units", "inches", "{case}/view1.png"],
            "choose pixels, normalized, per-mille",
        ),
        (
            ["--vlm", "replay:{case}/replay.jsonl", "--threshold", "2", "{case}/view1.png"],
            "--threshold",
        ),
    ],
)
def test_virf_perceive_refuses_bad_input_in_one_line(
    cli: Any, tmp_path: Path, args: list[str], says: str
) -> None:
    out = tmp_path / "scene.json"
    filled = [a.format(case=CASES / "correct", other=CASES / "wrong-material") for a in args]
    result = cli("perceive", *filled, "--out", out)
    assert result.exit_code == 2, result.output
    (line,) = [x for x in result.output.splitlines() if x.startswith("error:")]
    assert says in line
    assert "Traceback" not in result.output
    assert not out.exists()  # nothing half-written


def test_virf_plan_perceives_asks_and_refines(cli: Any) -> None:
    case = CASES / "low-confidence"
    result = cli(
        "plan",
        "--images",
        case / "view1.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--instruction",
        (case / "instruction.txt").read_text().strip(),
        "--planner",
        f"replay:{case / 'planner-replay.jsonl'}",
        "--answers",
        case / "answers.json",
        "--task-id",
        "perceived-mug",
        "--json",
    )
    assert result.exit_code == 1, result.output
    data = json.loads(result.stdout)
    statuses = [t["status"] for t in data["transcript"] if t["kind"] == "report"]
    # The uncertain material was a question; the answer made the hazard plain.
    assert statuses == ["UNKNOWN", "UNSAFE"]
    assert data["outcome"] == "TASK_REJECTED"
    both = cli(
        "plan",
        "--images",
        case / "view1.png",
        "--scene",
        case / "gold.json",
        "--instruction",
        "x",
        "--planner",
        "scripted",
    )
    assert both.exit_code == 2 and "one of them" in both.output


def test_bench_perception_scores_the_bundled_cases(cli: Any, tmp_path: Path) -> None:
    md = tmp_path / "perception.md"
    result = cli("bench", "perception", CASES, "--json", "--markdown", md)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    by_case = {(c["case"], c["mode"]): c for c in data["cases"]}
    assert by_case[("correct", "cascade")]["same_verdict"]
    assert by_case[("correct", "cascade")]["objects"]["f1"] == 1.0
    # A confident wrong material and a missed object lose the hazard: the
    # figures say so instead of hiding it.
    assert by_case[("wrong-material", "cascade")]["hazard_lost"]
    assert by_case[("missing-object", "cascade")]["objects"]["recall"] < 1
    assert (
        "StoveBurner_1 supports Towel_1"
        in by_case[("missing-object", "cascade")]["missing_safety_facts"]
    )
    # Uncertainty and disagreement end in UNKNOWN, never SAFE.
    assert by_case[("low-confidence", "cascade")]["perceived_verdict"] == "UNKNOWN"
    assert by_case[("views-disagree", "cascade")]["perceived_verdict"] == "UNKNOWN"
    assert by_case[("hybrid", "hybrid")]["objects"]["recall"] < 1
    assert "| hybrid | hybrid |" in md.read_text()


def test_a_runaway_object_list_is_refused_before_hundreds_of_requests(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    many = json.dumps({"objects": [{"category": "Apple"}] * 301})
    model = ScriptedApprentice([many])
    with pytest.raises(UnreadableReply, match="301 objects were listed; at most 300"):
        perceive([picture(tmp_path / "view1.png")], model, vocab, catalogue=catalogue)
    assert len(model.requests) == 1


# ---------------------------------------------------------------------------
# What a careless reading would have made SAFE, and replies that must not crash


def test_a_person_is_seen_and_a_child_near_a_lit_burner_is_not_safe(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    assert catalogue.match("Child").type == "Child"
    burner = {"bbox": [300, 260, 400, 300], "category": "StoveBurner"}
    knob = {"bbox": [420, 320, 450, 350], "category": "StoveKnob"}
    child = {"bbox": [450, 100, 560, 300], "category": "child"}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, burner, knob, child],
                [
                    STONE,
                    {"state": ["lit"], "material": "metal"},
                    {"state": ["on"], "material": "plastic"},
                    {"state": [], "material": "fabric"},
                ],
                [
                    on("StoveBurner_1", "CounterTop_1"),
                    {"first": "child_1", "relationship": "next to", "second": "StoveBurner_1"},
                ],
            )
        ],
    )
    scene = build_scene(result.scene, vocab)
    assert scene.objects["Child_1"] == frozenset({"Child"})
    # 'lit' is on; a person's material reading is left out, not a contradiction.
    assert Fact("StoveBurner_1", "hasState", "OnState") in scene.facts
    assert not any(f.subject == "Child_1" and f.predicate == "hasMaterial" for f in scene.facts)
    assert tutor.verify(result.scene, ["find StoveKnob", "turn_off StoveKnob"]).status != "SAFE"


def test_a_reply_without_a_material_asks_instead_of_taking_the_default(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue, tutor: LogicTutor
) -> None:
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, MICROWAVE, BOWL],
                [STONE, CLOSED_METAL, {"state": ["empty"]}],
                KITCHEN_PLACES,
            )
        ],
    )
    # A bowl is usually ceramic, but nobody saw that this one is.
    assert {
        "subject": "Bowl_1",
        "property": "hasMaterial",
        "object": "UnknownMaterial",
    } in result.scene["assertions"]
    assert tutor.verify(result.scene, PLAN_MICROWAVE_BOWL).status == "UNKNOWN"


def test_two_unboxed_objects_of_one_kind_are_not_described_alike(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    model = ScriptedApprentice(
        [
            json.dumps({"objects": [COUNTER, {"category": "Mug"}, {"category": "Mug"}]}),
            json.dumps(STONE),
            json.dumps({"locations": []}),
        ]
    )
    result = perceive([picture(tmp_path / "view1.png")], model, vocab, catalogue=catalogue)
    assert [r.method for r in model.requests] == ["detect", "attributes:1:CounterTop", "relations"]
    assert {r.purpose for r in model.requests} == {Purpose.PERCEIVE}
    for mug in ("Mug_1", "Mug_2"):
        assert {
            "subject": mug,
            "property": "hasMaterial",
            "object": "UnknownMaterial",
        } in result.scene["assertions"]


def test_partial_ids_fall_back_to_position_and_keep_the_disagreement(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies([COUNTER, {**BOWL, "id": "b"}], [STONE, bowl("metal")], []),
            replies([COUNTER, BOWL], [STONE, bowl("ceramic")], []),
        ],
    )
    assert [o.name for o in result.graph.objects if o.type == "Bowl"] == ["Bowl_1"]
    assert any("material read as Ceramic and Metal" in d for d in result.graph.disagreements)


def test_a_cycle_and_a_crowded_hand_are_resolved_not_crashed(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    robot = {"bbox": [500, 50, 600, 300], "category": "Robot"}
    knife = {"bbox": [200, 260, 260, 280], "category": "Knife"}
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [COUNTER, BOWL, knife, robot],
                [STONE, bowl("metal"), bowl("metal"), {"state": [], "material": "metal"}],
                [
                    on("Bowl_1", "CounterTop_1", 0.9),
                    on("CounterTop_1", "Bowl_1", 0.6),
                    {
                        "first": "Knife_1",
                        "relationship": "held",
                        "second": "Robot_1",
                        "confidence": 0.9,
                    },
                    {
                        "first": "Bowl_1",
                        "relationship": "held",
                        "second": "Robot_1",
                        "confidence": 0.95,
                    },
                ],
            )
        ],
    )
    build_scene(result.scene, vocab)  # a world that can exist
    said = " | ".join(result.graph.disagreements)
    assert "would close a cycle" in said or "is read as holding" in said


@pytest.mark.parametrize(
    "reply",
    [
        '{"objects": [{"category": "Mug", "bbox": [' + "9" * 400 + ", 1, 2, 3]}]}",
        '{"objects": [{"category": "Mug", "confidence": ' + "1" * 5000 + "}]}",
        '{"objects": [{"category": 7}]}',
        '{"objects": "many"}',
    ],
)
def test_odd_detection_replies_are_one_line_errors(
    reply: str, tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    with pytest.raises(UnreadableReply):
        perceive(
            [picture(tmp_path / "view1.png")],
            ScriptedApprentice([reply]),
            vocab,
            catalogue=catalogue,
        )


def test_boxes_in_other_units_are_cropped_where_they_say(
    tmp_path: Path, vocab: Vocabulary, catalogue: Catalogue
) -> None:
    result = run(
        tmp_path,
        vocab,
        catalogue,
        [
            replies(
                [
                    {"bbox": [0, 625, 1000, 1000], "category": "CounterTop"},
                    {"bbox": [515, 500, 672, 625], "category": "Bowl"},
                    {"bbox": [1e308, 0, 1e308, 1], "category": "Fork"},
                ],
                [STONE, bowl("metal"), bowl("metal")],
                [on("Bowl_1", "CounterTop_1")],
            )
        ],
        bbox_units="per-mille",
    )
    (bowl_seen,) = next(o for o in result.graph.objects if o.name == "Bowl_1").seen
    assert bowl_seen.bbox == (515.0, 500.0, 672.0, 625.0)


def test_broken_images_and_detector_files_are_refused_before_any_call(
    tmp_path: Path, vocab: Vocabulary
) -> None:
    image = picture(tmp_path / "view1.png")
    cut = tmp_path / "cut.png"
    cut.write_bytes(image.read_bytes()[:400])
    model = ScriptedApprentice([])
    with pytest.raises(InputError, match=r"cut\.png is not an image"):
        perceive([cut], model, vocab)
    bad = tmp_path / "boxes.json"
    for images, says in (
        ([{"id": [1], "file_name": "view1.png"}], "needs a number or string 'id'"),
        (
            [{"id": 1, "file_name": "view1.png"}, {"id": 2, "file_name": "x/view1.png"}],
            "repeats the file name",
        ),
    ):
        bad.write_text(json.dumps({"images": images, "annotations": [], "categories": []}))
        with pytest.raises(InputError, match=says):
            perceive([image], model, vocab, detections=bad)
    assert model.requests == []


def test_model_labels_are_printed_as_text_not_markup(cli: Any, tmp_path: Path) -> None:
    image = picture(tmp_path / "view1.png")
    digest = hashlib.sha256(image.read_bytes()).hexdigest()[:16]
    lines = [
        {
            "method": "detect",
            "text": json.dumps(
                {"objects": [{"category": "mug [/]", "bbox": [330, 240, 430, 300]}]}
            ),
        },
        {"method": "attributes:1:mug [/]", "text": json.dumps(bowl("ceramic"))},
        {"method": "relations", "text": json.dumps({"locations": []})},
    ]
    replay = tmp_path / "replay.jsonl"
    replay.write_text(
        "".join(
            json.dumps({"task_id": f"perceive:{digest}", "iteration": 1, **x}) + "\n" for x in lines
        )
    )
    result = cli("perceive", image, "--vlm", f"replay:{replay}")
    assert result.exit_code == 0, result.output
    assert "mug [/]" in result.output


def test_outputs_are_checked_before_the_model_is_asked(cli: Any, tmp_path: Path) -> None:
    case = CASES / "correct"
    out = tmp_path / "scene.json"
    result = cli(
        "perceive",
        case / "view1.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--out",
        out,
        "--graph",
        tmp_path / "missing" / "graph.json",
    )
    assert result.exit_code == 2 and "does not exist" in result.output
    assert not out.exists()
    empty = cli(
        "plan",
        "--images",
        case / "view1.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--instruction",
        " ",
        "--planner",
        "scripted",
        "--scene-out",
        out,
    )
    assert empty.exit_code == 2 and "--instruction is empty" in empty.output
    assert not out.exists()
    stray = cli(
        "plan",
        "--scene",
        case / "gold.json",
        "--instruction",
        "x",
        "--planner",
        "scripted",
        "--detections",
        case / "gold.json",
    )
    assert stray.exit_code == 2 and "--detections is for camera images" in stray.output


def test_the_same_images_give_the_same_scene_byte_for_byte(cli: Any) -> None:
    case = CASES / "views-disagree"
    args = (
        "perceive",
        case / "view1.png",
        case / "view2.png",
        "--vlm",
        f"replay:{case / 'replay.jsonl'}",
        "--json",
    )
    assert cli(*args).stdout == cli(*args).stdout
