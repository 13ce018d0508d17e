# The Teleworkbench emulator: one image for the server and the robot agents.
#   docker build -t teleworkbench .
#   docker run -p 8000:8000 teleworkbench up --host 0.0.0.0 --port 8000
# The project is installed from its wheel (migrations and dashboard are package data; the top-level
# alembic/ directory goes in as server/migrations), so the image holds no source tree; the build
# stage makes the wheels (scikit-fmm compiles there).
FROM python:3.11-slim AS build
RUN apt-get update \
 && apt-get install -y --no-install-recommends gcc g++ \
 && rm -rf /var/lib/apt/lists/*
WORKDIR /src
COPY pyproject.toml README.md ./
COPY contract contract
COPY planners planners
COPY robot_agent robot_agent
COPY server server
COPY alembic alembic
COPY client_sdk client_sdk
COPY twb twb
RUN pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
# bubblewrap: the sandbox of uploaded programs; libseccomp2: its system-call allowlist (docs/security.md).
# Under Docker's default seccomp profile bwrap cannot make its namespaces (docs/uploads.md, "Caveats").
RUN apt-get update \
 && apt-get install -y --no-install-recommends bubblewrap libseccomp2 \
 && rm -rf /var/lib/apt/lists/*
COPY --from=build /wheels /wheels
RUN pip install --no-cache-dir --no-index --find-links /wheels teleworkbench && rm -rf /wheels
# compile the simulation kernels into the image (numba's cache), not at every container start
RUN python -c "from robot_agent.engine.sim import warm_up; warm_up()"
WORKDIR /data
EXPOSE 8000 5555
ENTRYPOINT ["twb"]
CMD ["up", "--host", "0.0.0.0", "--port", "8000", "--data-dir", "/data"]
