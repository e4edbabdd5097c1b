# The two commands of the README. Both set up what is missing first (idempotent, tools/bootstrap.sh).
SHELL := /bin/bash
.PHONY: setup demo test bench lint clean

setup:
	@bash tools/bootstrap.sh

demo: setup
	@source tools/env.sh && avp demo --seed $${SEED:-1} --method $${METHOD:-bezier} \
		$${REALTIME:+--realtime}

test: setup
	@source tools/env.sh && python -m pytest -q tests

bench: setup
	@source tools/env.sh && python bench/bench_sensing.py

lint: setup
	@source tools/env.sh && python -m ruff check src tests bench tools

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log ros2_ws/.build.sha1 out
