# Two front-door targets: `make demo` and `make test`. Both set everything up first.
.PHONY: setup demo test test-slow bench

setup:
	bash scripts/setup.sh

demo: setup
	bash scripts/demo.sh

test: setup
	.venv/bin/python -m pytest -q

test-slow: setup
	.venv/bin/python -m pytest -q -m slow || [ $$? -eq 5 ]  # exit 5: no slow tests collected

bench: setup
	.venv/bin/python benchmarks/render.py
	.venv/bin/python benchmarks/placement.py
	.venv/bin/python benchmarks/similarity.py
