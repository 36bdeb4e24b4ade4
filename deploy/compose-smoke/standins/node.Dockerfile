# Stands in for node:20-bookworm-slim: Debian's Node.js and npm (enough for `npm ci` of web/).
ARG BASE
FROM ${BASE}
RUN apt-get update \
    && apt-get install -y --no-install-recommends nodejs npm \
    && rm -rf /var/lib/apt/lists/*
CMD ["node"]
