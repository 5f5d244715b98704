"""Automatic observation programs: a target list, a night's plan, and its execution.

::

    from virtualstar.planning import load_program, plan_program, PlanRequest
    program = load_program("catalogs/data/program-example.toml")
    plan = plan_program(PlanRequest(program, start_us, end_us, site))
    plan.blocks, plan.left_out, plan.as_dict()
"""

from .exceptions import PlanFileError, PlanningError, ProgramError
from .planner import PlanRequest, plan_program
from .program import Program, ProgramTarget, load_program
from .scheduler import Block, Plan

__all__ = ["Block", "Plan", "PlanFileError", "PlanRequest", "PlanningError", "Program",
           "ProgramError", "ProgramTarget", "load_program", "plan_program"]
