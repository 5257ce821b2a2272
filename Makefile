# Two front-door targets: `make demo` and `make test`. Both set everything up first.
.PHONY: setup demo test test-slow bench

setup:
	bash scripts/setup.sh

demo: setup
	bash scripts/demo.sh

# Tests run in a fresh temporary folder named as pytest's first run on a machine names its own
# (pytest-of-USER/pytest-0): what a fresh clone on a new machine sees, whatever ran here before.
TEST_TMP = .pytest-tmp

test: setup
	rm -rf $(TEST_TMP) && mkdir -p $(TEST_TMP)  # pytest makes the basetemp, not its parent
	.venv/bin/python -m pytest -q --basetemp $(TEST_TMP)/pytest-0

test-slow: setup
	rm -rf $(TEST_TMP) && mkdir -p $(TEST_TMP)  # pytest makes the basetemp, not its parent
	.venv/bin/python -m pytest -q -m slow --basetemp $(TEST_TMP)/pytest-0 || [ $$? -eq 5 ]  # exit 5: no slow tests collected

bench: setup
	.venv/bin/python benchmarks/render.py
	.venv/bin/python benchmarks/placement.py
	.venv/bin/python benchmarks/similarity.py
