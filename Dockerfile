# The Teleworkbench emulator: one image for the server and the robot agents.
#   docker build -t teleworkbench .
#   docker run -p 8000:8000 teleworkbench up --host 0.0.0.0 --port 8000
FROM python:3.11-slim

# scikit-fmm builds from source
RUN apt-get update \
 && apt-get install -y --no-install-recommends gcc g++ \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY pyproject.toml README.md ./
COPY planners planners
COPY robot_agent robot_agent
COPY server server
COPY client_sdk client_sdk
COPY twb twb
COPY alembic alembic
COPY alembic.ini ./
# editable: the server finds its Alembic migrations next to the code
RUN pip install --no-cache-dir -e .
# compile the simulation kernels into the image (numba's cache), not at every container start
RUN python -c "from robot_agent.sim import warm_up; warm_up()"

EXPOSE 8000 5555
ENTRYPOINT ["twb"]
CMD ["up", "--host", "0.0.0.0", "--port", "8000", "--data-dir", "/data"]
