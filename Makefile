.DEFAULT_GOAL := help

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-12s %s\n", $$1, $$2}'

install:  ## build and install phloem with the test extras
	pip install ".[test]"

dev:  ## build the extension in release mode into the current environment (maturin develop)
	maturin develop --release

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

.PHONY: help install dev test lint bench peers sheet
