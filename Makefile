# Convenience targets; each calls the scripts the README documents.
.PHONY: install test test-serial demo lint clean
install:
	bash scripts/install.sh
test:
	bash scripts/test.sh
test-serial: install
	.venv/bin/python -m pytest -q
demo:
	bash scripts/demo.sh
lint:
	.venv/bin/python -m ruff check app meshes tests || echo "ruff not installed: pip install ruff into .venv"
clean:
	rm -rf results .pytest_cache
