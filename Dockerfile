# The Driving Arena service image: API (`arena serve`), worker (`arena worker`) and admin CLI.
#   docker build -t driving-arena:latest .
# Agents never run in this image: the worker starts them in the agent runtime image
# (Dockerfile.agent) through the host's Docker daemon. See docs/deployment.md.
# BASE_IMAGE: a Debian-based image with Python 3.11 and pip, pinned by digest (no default: a tag
# moved upstream must not change what is built): `python:3.11-slim@sha256:...`, as
# scripts/pin_images.py prints it from the pulled image. Hosts without a registry build one offline
# (scripts/build_offline_images.py: Debian packages, local wheels, no network).
ARG BASE_IMAGE

# The simulator's compiled core (setup.py, sim/compiled.py) needs a C compiler, which the base
# has not: its modules are built in this stage and copied into the service image below. (The
# offline base has the compiler and Python's headers already: it cannot reach apt.)
FROM ${BASE_IMAGE} AS core
ARG BUILD_PACKAGES="gcc libc6-dev"
RUN dpkg-query -W $BUILD_PACKAGES >/dev/null 2>&1 || { \
        apt-get update \
        && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
            $BUILD_PACKAGES \
        && rm -rf /var/lib/apt/lists/*; }
WORKDIR /src
COPY pyproject.toml setup.py ./
COPY sim ./sim
# Every .pyx must become a module: setup.py's extensions are optional (a host without a compiler
# installs without them), the image must not be.
RUN python -c "import tomllib; print(*tomllib.load(open('pyproject.toml', 'rb'))['build-system']['requires'], sep='\n')" > /tmp/build-requirements.txt \
    && pip install --no-cache-dir -r /tmp/build-requirements.txt \
    && python setup.py build_ext --inplace \
    && test "$(find sim -name '*.so' | wc -l)" -eq "$(find sim -name '*.pyx' | wc -l)" \
    && mkdir /core && find sim -name '*.so' -exec cp --parents {} /core \;

FROM ${BASE_IMAGE}

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    ARENA_DATA_DIR=/srv/arena

# libsumo and SUMO's binaries (from the eclipse-sumo wheel) link these system libraries
# (installed unless the base has them already: an offline base cannot reach apt).
ARG SYSTEM_LIBRARIES="libgl1 libx11-6 libxext6 libxrender1 libatomic1 libexpat1 zlib1g"
RUN dpkg-query -W $SYSTEM_LIBRARIES >/dev/null 2>&1 || { \
        apt-get update \
        && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
            $SYSTEM_LIBRARIES \
        && rm -rf /var/lib/apt/lists/*; }

WORKDIR /app
# Only what the service needs (no tests, benchmarks or local data). Dependencies first, from
# pyproject.toml alone, so that a code change reuses their layer.
COPY pyproject.toml ./
RUN python -c "import tomllib; print(*tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies'], sep='\n')" > /tmp/requirements.txt \
    && pip install --no-cache-dir -r /tmp/requirements.txt \
    && rm -rf /root/.cache /tmp/requirements.txt
COPY README.md alembic.ini setup.py ./
COPY build_backend ./build_backend
COPY migrations ./migrations
COPY arena ./arena
COPY agent_runtime ./agent_runtime
COPY sim ./sim
COPY scenarios ./scenarios
COPY submissions ./submissions
COPY evaluator ./evaluator
COPY learn ./learn
COPY server ./server
COPY arena_command ./arena_command
# The example agents: the team's code, outside our packages, but the planner is the reference
# expert of the solvability check and of the public replays (arena/examples.py).
COPY examples ./examples
COPY docs ./docs
COPY --from=core /core/sim ./sim
# Editable, so `arena admin db upgrade` finds alembic.ini and migrations/ next to the code; the
# compiled core is in place (ARENA_CORE_PREBUILT: nothing to build), and must load.
RUN ARENA_CORE_PREBUILT=1 pip install --no-cache-dir --no-deps -e . && rm -rf /root/.cache \
    && python -c "from sim.compiled import core_status; s = core_status(); assert s == 'compiled', s"

# /var/lib/arena-api: the API's own scratch in docker-compose.yml (a volume starts with this
# folder's owner).
RUN useradd --system --uid 1000 --home-dir /srv/arena arena \
    && mkdir -p /srv/arena /var/lib/arena-api && chown arena /srv/arena /var/lib/arena-api
VOLUME ["/srv/arena"]
EXPOSE 8000

# The API runs unprivileged; the worker service overrides the user (it needs the Docker socket).
USER arena
HEALTHCHECK --interval=15s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import httpx,sys; sys.exit(httpx.get('http://127.0.0.1:8000/api/v1/healthz').status_code != 200)"]
CMD ["arena", "serve", "--host", "0.0.0.0", "--port", "8000", "--workers", "2"]
