# tacit: set-up, main job and tests on a fresh Debian machine.
SUDO := $(shell [ "$$(id -u)" -eq 0 ] || echo sudo)
PKGS := build-essential pkg-config libhdf5-dev fonts-dejavu-core
TACIT := ./target/release/tacit

.PHONY: setup demo test python bench check

## Install the system packages tacit needs (only those missing).
setup:
	@missing=""; for p in $(PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
		echo "installing:$$missing"; \
		$(SUDO) apt-get update && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y $$missing; \
	fi

## Main job: build, then diagnose the record shipped in data/ (validation on a second record).
demo: setup
	cargo build --release
	$(TACIT) diagnose --model data/lanl8dof.toml --record data/lanl8dof-bumper.h5 \
		--validate data/lanl8dof-bumper-validation.h5 -o out/demo --force
	@echo "main job done: report in out/demo/report.md (machine-readable: out/demo/report.json)"

## The test suite (what CI runs), on the release build `make demo` made.
test: setup
	cargo test --release

## The Python package (python/): a virtual environment in .venv, the
## extension built on the release build (maturin), its tests (pytest).
python: setup
	@dpkg -s python3-venv python3-dev >/dev/null 2>&1 || { $(SUDO) apt-get update && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y python3-venv python3-dev; }
	python3 -m venv .venv
	.venv/bin/pip install -q maturin pytest numpy scipy
	. .venv/bin/activate && maturin develop --release -m python/Cargo.toml
	.venv/bin/python -m pytest -q python/tests

## Benchmarks (release, criterion).
bench: setup
	cargo bench

## Lints, as CI runs them.
check:
	cargo fmt --check
	cargo clippy --release --all-targets -- -D warnings
