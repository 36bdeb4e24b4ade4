# Stands in for eclipse/zenoh: a Zenoh router from the project image's eclipse-zenoh (Python),
# started the same way (`-c /etc/zenoh/zenoh.json5`, the compose file's command).
ARG PICKPLACE_IMAGE
FROM ${PICKPLACE_IMAGE}
COPY zenoh_router.py /usr/local/bin/zenoh_router.py
EXPOSE 7447
ENTRYPOINT ["python", "/usr/local/bin/zenoh_router.py"]
CMD ["-c", "/etc/zenoh/zenoh.json5"]
