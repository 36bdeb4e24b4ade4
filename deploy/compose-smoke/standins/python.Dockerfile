# Stands in for python:3.11-slim-bookworm: Debian's Python 3.11 with venv, `python` on PATH.
ARG BASE
FROM ${BASE}
RUN apt-get update \
    && apt-get install -y --no-install-recommends python3 python3-venv python-is-python3 \
    && rm -rf /var/lib/apt/lists/*
CMD ["python3"]
