# The two commands of the README. Both set up what is missing first (idempotent, tools/bootstrap.sh).
SHELL := /bin/bash
.PHONY: setup demo test test-fast stress-dds bench lint clean records-check

setup:
	@bash tools/bootstrap.sh

demo: setup
	@source tools/env.sh && avp demo --seed $${SEED:-1} --method $${METHOD:-bezier} \
		$${REALTIME:+--realtime}

test: setup
	@source tools/env.sh && python -m pytest -q tests

# the unit tests alone: no node processes, no Ray cluster (the markers of tests/conftest.py)
test-fast: setup
	@source tools/env.sh && python -m pytest -q -m "not dds and not ray" tests

# the DDS tests RUNS times in a row beside HOGS busy loops, to catch discovery races before CI does
stress-dds: setup
	@source tools/env.sh && python tools/stress_dds.py --runs $${RUNS:-10} --hogs $${HOGS:-2}

bench: setup
	@source tools/env.sh && python bench/bench_sensing.py

# Did a change alter the paper lot's episodes? 50 seeds x 8 methods x 2 modes in both protocols (about 10 min on
# 2 cores), checked against the committed digests (tools/records_digest.py; docs/experiment.md "Records check").
RECORD_METHODS := bezier,constant_velocity,hybrid_astar,learned,implicit,nawaz,oracle,blind
records-check: setup
	@source tools/env.sh && for p in default paper; do \
		rm -rf out/records_check/$$p && \
		avp experiment --protocol $$p --scenarios 50 --mode both --methods $(RECORD_METHODS) \
			--workers $${WORKERS:-2} --no-progress --out out/records_check/$$p > /dev/null && \
		echo "protocol $$p:" && \
		python tools/records_digest.py check out/records_check/$$p docs/results/reference_records/$${p}_50x8x2.json \
			|| exit 1; done

lint: setup
	@source tools/env.sh && python -m ruff check src tests bench tools

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log ros2_ws/.build.sha1 out
