# One image for the API and the workers (docker-compose.yml runs it with different commands).
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY motion motion
COPY engines engines
COPY schemas schemas
COPY service service
COPY workers workers
COPY web web
RUN pip install --no-cache-dir .
ENV SEGUE_DATA_DIR=/data
EXPOSE 8000
CMD ["segue", "serve", "--host", "0.0.0.0", "--port", "8000"]
