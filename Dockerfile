# One image for the API and the workers (docker-compose.yml and deploy/*.compose.yml run it with
# different commands; tag it with the package version, segue:0.1.0: an API and its workers must run
# the same one). Its /data is a cache only when SEGUE_STORE_URL names an object store (MinIO, no
# shared volume); without SEGUE_STORE_URL it is the store itself (mount a volume to keep it).
# The base image is pinned (a Python patch release on a Debian release), never a moving tag.
FROM python:3.11.9-slim-bookworm
WORKDIR /app
COPY pyproject.toml README.md ./
COPY motion motion
COPY engines engines
COPY schemas schemas
COPY service service
COPY workers workers
COPY web web
# the s3 extra: boto3, for SEGUE_STORE_URL=s3://... (MinIO in docker-compose.yml)
RUN pip install --no-cache-dir ".[s3]"
# the control engine's compiled kernels, compiled once into the image (numba keys them by the
# installed sources): no container pays the ~15 CPU-s compile on its first job
ENV NUMBA_CACHE_DIR=/opt/segue/numba
RUN segue warm && chmod -R a+rX /opt/segue/numba
ENV SEGUE_DATA_DIR=/data
EXPOSE 8000
CMD ["segue", "serve", "--host", "0.0.0.0", "--port", "8000"]
