.DEFAULT_GOAL := help

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-12s %s\n", $$1, $$2}'

install:  ## build and install phloem with the test extras
	pip install ".[test]"

dev:  ## build the extension in release mode into the current environment (maturin develop)
	maturin develop --release

DIST ?= dist
wheel:  ## build the abi3 wheel for this platform into dist/ (PyPI-compatible manylinux tag, embedded data inside)
	maturin build --release --compatibility pypi --auditwheel check --out $(DIST)

test: install  ## every test: Rust unit tests and pytest (what CI runs)
	cargo test --release -p phloem-core && pytest

lint:  ## ruff, ruff format, mypy --strict, stubtest, rustfmt and clippy (what CI runs after the tests)
	ruff check .
	ruff format --check .
	mypy --strict python/phloem
	python -m mypy.stubtest phloem._core
	cargo fmt --all -- --check
	cargo clippy --workspace --all-targets -- -D warnings

bench:  ## Rust criterion benches and Python benchmarks
	cargo bench -p phloem-core --bench patch
	cargo bench -p phloem-core --bench seams
	cargo bench -p phloem-core --bench blend
	cargo bench -p phloem-core --bench shapes
	cargo bench -p phloem-core --bench tbn
	cargo bench -p phloem-core --bench mvc
	pytest benches/python --benchmark-enable --benchmark-only

peers:  ## side-by-side runs against PyPatchMatch, resynthesizer, texture-synthesis
	python benches/peers/peers.py

sheet:  ## contact sheets of the texture, graph-cut, shape, bark and tree jobs (out/*_sheet.png)
	python -m benches.sheets.sheet_texture out/texture_sheet.png
	python -m benches.sheets.sheet_seams out/seams_sheet.png
	python -m benches.sheets.sheet_bark out/bark_sheet.png
	python -m benches.sheets.sheet_shapes out/shapes_sheet.png
	python -m benches.sheets.sheet_by_numbers out/by_numbers_sheet.png
	python -m benches.sheets.sheet_trees out/trees_sheet.png
	python -m benches.sheets.sheet_tree_variations out/tree_variations_sheet.png
	python -m benches.sheets.sheet_branching_trace --out out/branching_trace_sheet.png
	python -m benches.sheets.sheet_branching_image --out out/branching_image_sheet.png
	python -m benches.sheets.sheet_branching out/branching_sheet.png

FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?= skeleton guide trunk_model label_map mask image strokes svg
FUZZ_OUT ?= out/fuzz
FUZZ_FLAGS = -max_total_time=$(FUZZ_SECONDS) -timeout=10 -rss_limit_mb=2048 -print_final_stats=1

fuzz:  ## run each fuzz target for FUZZ_SECONDS (default 60) on fuzz/corpus; needs ".[fuzz]"; not in CI
	@status=0; for t in $(FUZZ_TARGETS); do \
	  mkdir -p $(FUZZ_OUT)/corpus/$$t $(FUZZ_OUT)/crashes/$$t; \
	  before=$$(ls $(FUZZ_OUT)/crashes/$$t | wc -l); echo "== fuzz $$t ($(FUZZ_SECONDS) s)"; \
	  python fuzz/fuzz_$$t.py $(FUZZ_FLAGS) -artifact_prefix=$(FUZZ_OUT)/crashes/$$t/ \
	    $(FUZZ_OUT)/corpus/$$t fuzz/corpus/$$t 2>&1 | grep -v '^INFO: Instrumenting' || true; \
	  if [ "$$(ls $(FUZZ_OUT)/crashes/$$t | wc -l)" != "$$before" ]; then echo "== fuzz $$t: new crash in $(FUZZ_OUT)/crashes/$$t"; status=1; fi; \
	done; exit $$status

fuzz-merge:  ## minimise the new inputs of make fuzz (out/fuzz/corpus) into fuzz/corpus, for review and commit
	@for t in $(FUZZ_TARGETS); do \
	  python fuzz/fuzz_$$t.py -merge=1 fuzz/corpus/$$t $(FUZZ_OUT)/corpus/$$t 2>&1 | grep -v '^INFO: Instrumenting' | tail -1; \
	done

.PHONY: help install dev wheel test lint bench peers sheet fuzz fuzz-merge
