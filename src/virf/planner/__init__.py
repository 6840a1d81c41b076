"""The apprentice side of VIRF: LLM planner clients, offline planners and the run log."""

from __future__ import annotations

from virf.migrations import Migration
from virf.planner.apprentices import (
    Apprentice,
    Attachment,
    Proposal,
    ProposalRequest,
    Purpose,
    ReplayApprentice,
    ScriptedApprentice,
    export_replay,
    load_replay,
)
from virf.planner.chat import ClientSettings, Endpoint
from virf.planner.clients import OpenAIApprentice
from virf.planner.deadline import Deadline
from virf.planner.factory import make_apprentice
from virf.planner.runlog import MIGRATIONS, CallRecord, RunLog
from virf.planner.spec import PlannerKind, PlannerSpec

__all__ = [
    "MIGRATIONS",
    "Apprentice",
    "Attachment",
    "CallRecord",
    "ClientSettings",
    "Deadline",
    "Endpoint",
    "Migration",
    "OpenAIApprentice",
    "PlannerKind",
    "PlannerSpec",
    "Proposal",
    "ProposalRequest",
    "Purpose",
    "ReplayApprentice",
    "RunLog",
    "ScriptedApprentice",
    "export_replay",
    "load_replay",
    "make_apprentice",
]
