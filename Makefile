# Two commands for a new user: `make demo` and `make test`. Both set up .venv first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEMO_ROOT ?= data/synthetic/default
DEMO_DATA := $(DEMO_ROOT)/nuscenes
DEMO_WORKSPACE := $(DEMO_ROOT)/workspace
DEMO_SITE ?= site-001

.PHONY: demo test setup lint clean frontend chromium postgresql

# The browser editor: `npm ci` when the lock file changed, the Vite build when its output is older than a source.
FRONTEND := app/frontend
FRONTEND_INSTALLED := $(FRONTEND)/node_modules/.package-lock.json
FRONTEND_BUILT := $(FRONTEND)/dist/index.html
FRONTEND_SOURCES := $(shell find $(FRONTEND)/src -type f) $(addprefix $(FRONTEND)/,index.html vite.config.js package.json)
# Debian's Chromium for the browser tests, installed only when missing.
CHROMIUM := /usr/bin/chromium
# Debian's PostgreSQL server programs: the backend tests also run on a throwaway PostgreSQL cluster.
INITDB := $(firstword $(wildcard /usr/lib/postgresql/*/bin/initdb))

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python requirements.lock pyproject.toml
	$(BIN)/pip install --quiet pip==26.3
	$(BIN)/pip install --quiet -r requirements.lock
	$(BIN)/pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

setup: $(STAMP) frontend

$(FRONTEND_INSTALLED): $(FRONTEND)/package-lock.json
	cd $(FRONTEND) && npm ci --no-audit --no-fund

$(FRONTEND_BUILT): $(FRONTEND_INSTALLED) $(FRONTEND_SOURCES)
	cd $(FRONTEND) && npm run build

frontend: $(FRONTEND_BUILT)

$(CHROMIUM):
	apt-get update && apt-get install -y chromium

chromium: $(CHROMIUM)

postgresql:
ifeq ($(INITDB),)
	apt-get update && apt-get install -y postgresql
endif

# The whole path on the default synthetic site (each stage skips what is up to date), then the editor on the
# reconstructed rasters with the VMA proposals, and the viser 3D review beside it.
demo: $(STAMP) frontend
	$(BIN)/cama synth --preset default --out $(DEMO_ROOT)
	$(BIN)/cama run $(DEMO_DATA)
	$(BIN)/cama demo $(DEMO_ROOT) --proposals $(DEMO_WORKSPACE)/proposals/$(DEMO_SITE).json \
		--rasters $(DEMO_WORKSPACE)/surface/$(DEMO_SITE)/bev

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy annotations app cama_pipeline models cama_studio

test: $(STAMP) frontend chromium postgresql
	$(MAKE) lint
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) data
