# The two commands of the README. Both set up what is missing first (idempotent, tools/bootstrap.sh).
SHELL := /bin/bash
.PHONY: setup demo test test-fast stress-dds bench lint clean records-check results results-table

setup:
	@bash tools/bootstrap.sh

demo: setup
	@source tools/env.sh && avp demo --seed $${SEED:-1} --method $${METHOD:-bezier} \
		$${REALTIME:+--realtime}

# Every test, TEST_WORKERS (4) test processes at once (pytest-xdist; a module's tests stay in one process, each DDS
# test holds a ROS domain of its own). TEST_WORKERS=0 runs them one after another.
test: setup
	@source tools/env.sh && w=$${TEST_WORKERS:-4} && \
		python -m pytest -q $$( [ "$$w" = 0 ] || echo "-n $$w --dist loadgroup" ) tests

# the fast unit tests alone: no node processes, no Ray cluster, no test marked slow (tests/conftest.py, pyproject.toml)
test-fast: setup
	@source tools/env.sh && w=$${TEST_WORKERS:-2} && \
		python -m pytest -q $$( [ "$$w" = 0 ] || echo "-n $$w --dist loadgroup" ) -m "not dds and not ray and not slow" tests

# the DDS tests RUNS times in a row beside HOGS busy loops, TEST_WORKERS at once as make test runs them, to catch
# discovery races before CI does
stress-dds: setup
	@source tools/env.sh && python tools/stress_dds.py --runs $${RUNS:-10} --hogs $${HOGS:-2} \
		--workers $${TEST_WORKERS:-4}

bench: setup
	@source tools/env.sh && python bench/bench_sensing.py

# Did a change alter the paper lot's episodes? 50 seeds x 8 methods x 2 modes in both protocols (about 10 min on
# 2 cores), checked against the committed digests (tools/records_digest.py; docs/experiment.md "Records check").
RECORD_METHODS := bezier,constant_velocity,hybrid_astar,learned,implicit,nawaz,oracle,blind
records-check: setup
	@source tools/env.sh && rc=0 && for p in default paper; do \
		rm -rf out/records_check/$$p && \
		avp experiment --protocol $$p --scenarios 50 --mode both --methods $(RECORD_METHODS) \
			--workers $${WORKERS:-2} --no-progress --out out/records_check/$$p > /dev/null || exit 2; \
		echo "protocol $$p:"; \
		python tools/records_digest.py check out/records_check/$$p docs/results/reference_records/$${p}_50x8x2.json \
			|| rc=1; done; exit $$rc

# Every figure of the README's results table (config/suites/headline.yaml): `make results` runs the whole suite into
# out/results (hours on 2 cores; resumable, WORKERS=N, or BACKEND=ray), `make results QUICK=1` a small one into
# out/results_quick (minutes). Each writes OUT/headline.md. `make results-table` regenerates the README's table from
# the committed records (docs/experiment.md, "The headline table").
results: setup
	@source tools/env.sh && out=$${OUT:-out/results$(if $(QUICK),_quick)} && \
		avp experiment --suite headline $(if $(QUICK),--quick) --out $$out --workers $${WORKERS:-2} \
			--backend $${BACKEND:-local} --no-progress && cat $$out/headline.md

results-table: setup
	@source tools/env.sh && python -m avp_experiment.headline table --committed --json docs/results/headline.json \
		--readme README.md --results-page docs/results/README.md && \
		echo "README.md and docs/results/README.md: tables regenerated from docs/results/headline.json"

lint: setup
	@source tools/env.sh && python -m ruff check src tests bench tools

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log ros2_ws/.build.sha1 out
