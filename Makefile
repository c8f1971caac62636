# tacit: set-up, main job and tests on a fresh Debian machine.
SUDO := $(shell [ "$$(id -u)" -eq 0 ] || echo sudo)
PKGS := build-essential pkg-config libhdf5-dev fonts-dejavu-core
TACIT := ./target/release/tacit

.PHONY: setup demo test bench check

## Install the system packages tacit needs (only those missing).
setup:
	@missing=""; for p in $(PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
		echo "installing:$$missing"; \
		$(SUDO) apt-get update && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y $$missing; \
	fi

## Main job: build, then run it on the record shipped in data/.
demo: setup
	cargo build --release
	$(TACIT) modal --model data/lanl8dof.toml
	mkdir -p out/demo
	$(TACIT) simulate --model data/lanl8dof-contact.toml --input random --rms 20 --band 5,200 \
		--fs 512 --samples 4096 --sensors 1,5,6 --noise 0.01 --seed 7 -o out/demo/record.h5
	@echo "main job done: record in out/demo/record.h5"

## The test suite (what CI runs).
test: setup
	cargo test

## Benchmarks (release, criterion).
bench: setup
	cargo bench

## Lints, as CI runs them.
check:
	cargo fmt --check
	cargo clippy --all-targets -- -D warnings
