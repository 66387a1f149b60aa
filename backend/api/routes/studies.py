"""``/api/studies``: start a design study (the study file as JSON), list, progress and results, files."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException, Query, status
from fastapi.responses import FileResponse

from backend.api.deps import StudiesDep, TokenDep
from backend.api.schemas import StudyDetail, StudyLinks, StudyPlan, StudySummary
from backend.studies.manager import STUDY_FILES, StudyNotFound, StudyState
from twin.studies.report import best_cases, best_sentence, percentiles
from twin.studies.spec import StudySpec

router = APIRouter(prefix="/api/studies", tags=["studies"])


def links(study_id: str) -> StudyLinks:
    base = f"/api/studies/{study_id}"
    return StudyLinks(self=base, stop=f"{base}/stop", resume=f"{base}/resume", files=f"{base}/files/")


def summary(state: StudyState) -> StudySummary:
    return StudySummary(**{k: v for k, v in vars(state).items()}, links=links(state.id))


@router.post("", status_code=status.HTTP_201_CREATED, response_model=StudySummary, dependencies=[TokenDep],
             responses={422: {"description": "invalid study, or over this server's limits"}})
def start_study(studies: StudiesDep, study: Annotated[StudySpec, Body()]) -> StudySummary:
    """Queue a study (the study file of product.md as JSON); studies run one at a time on Dask."""
    return summary(studies.submit(study))


@router.post("/plan", response_model=StudyPlan,
             responses={422: {"description": "invalid study, or over this server's limits"}})
def plan_study(studies: StudiesDep, study: Annotated[StudySpec, Body()]) -> StudyPlan:
    """What a start would run: the cases (design points x seeds or samples), the workers, and an estimated
    wall time from this server's finished studies (``estimate_s`` null, with ``basis`` saying why, before any)."""
    return StudyPlan(**studies.plan(study))


@router.get("", response_model=list[StudySummary])
def list_studies(studies: StudiesDep) -> list[StudySummary]:
    """All studies, newest first, with their progress."""
    return [summary(s) for s in studies.all()]


@router.get("/{study_id}", response_model=StudyDetail, responses={404: {"description": "no such study"}})
def get_study(study_id: str, studies: StudiesDep,
              cases: Annotated[bool, Query(description="include the per-case rows")] = True) -> StudyDetail:
    """Progress, and when the study has ended: cases, best case per metric, percentiles, figures, downloads."""
    state = studies.get(study_id)
    doc = studies.request(study_id)
    result = studies.summary(study_id)
    base = f"/api/studies/{study_id}/files"
    detail: dict[str, Any] = {"study": doc, "figures": [f"{base}/figures/{n}" for n in studies.figures(study_id)]}
    detail["downloads"] = {n: f"{base}/{n}" for n in STUDY_FILES if (studies.folder(study_id) / n).is_file()}
    if result is not None:
        spec = StudySpec.model_validate(doc)
        detail["best"] = [{**b, "reading": best_sentence(b)} for b in best_cases(spec, result["cases"])]
        detail["percentiles"] = percentiles(result["cases"]) if spec.monte_carlo is not None else None
        detail["timing"] = result.get("timing")
        if cases:
            detail["cases"] = result["cases"]
    return StudyDetail(**summary(state).model_dump(), **detail)


@router.post("/{study_id}/stop", response_model=StudySummary, status_code=status.HTTP_202_ACCEPTED,
             dependencies=[TokenDep],
             responses={404: {"description": "no such study"}, 409: {"description": "the study is not going"}})
def stop_study(study_id: str, studies: StudiesDep) -> StudySummary:
    """Stop after the cases that are running; finished cases stay, and the study can resume."""
    return summary(studies.stop(study_id))


@router.post("/{study_id}/resume", response_model=StudySummary, status_code=status.HTTP_202_ACCEPTED,
             dependencies=[TokenDep],
             responses={404: {"description": "no such study"},
                        409: {"description": "the study is going or has finished"}})
def resume_study(study_id: str, studies: StudiesDep) -> StudySummary:
    """Queue an interrupted, stopped or failed study again: only its missing cases are computed."""
    return summary(studies.resume(study_id))


@router.get("/{study_id}/files/{name:path}", response_class=FileResponse,
            responses={200: {"content": {media: {} for media in (*STUDY_FILES.values(), "image/png")}},
                       404: {"description": "no such study or file"}})
def study_file(study_id: str, name: str, studies: StudiesDep) -> FileResponse:
    """results.parquet, results.csv, study.md, summary.json or figures/<name>.png."""
    try:
        path = studies.file(study_id, name)
    except StudyNotFound as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None
    media = STUDY_FILES.get(name, "image/png")
    return FileResponse(path, media_type=media, filename=f"{study_id}-{path.name}")
