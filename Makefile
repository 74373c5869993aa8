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
	pytest benches/bench_patch.py benches/bench_seams.py benches/bench_blend.py benches/bench_shapes.py benches/bench_tbn.py benches/bench_bark.py benches/bench_trees.py benches/bench_warp.py benches/bench_tree_variations.py benches/bench_branching_structure.py benches/bench_branching_trace.py benches/bench_branching_image.py --benchmark-enable --benchmark-only

peers:  ## side-by-side runs against PyPatchMatch, resynthesizer, texture-synthesis
	python benches/peers.py

sheet:  ## contact sheets of the texture, graph-cut, shape, bark and tree jobs (out/*_sheet.png)
	python benches/sheet_texture.py out/texture_sheet.png
	python benches/sheet_seams.py out/seams_sheet.png
	python benches/sheet_bark.py out/bark_sheet.png
	python benches/sheet_shapes.py out/shapes_sheet.png
	python benches/sheet_by_numbers.py out/by_numbers_sheet.png
	python benches/sheet_trees.py out/trees_sheet.png
	python benches/sheet_tree_variations.py out/tree_variations_sheet.png
	python benches/sheet_branching_trace.py --out out/branching_trace_sheet.png
	python benches/sheet_branching_image.py --out out/branching_image_sheet.png
	python benches/sheet_branching.py out/branching_sheet.png

.PHONY: help install dev test lint bench peers sheet
