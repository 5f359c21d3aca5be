"""Users: admins create and list them."""

import logging

from fastapi import APIRouter, status

from app.backend import crud
from app.backend.api.deps import AdminUser, SessionDep, SettingsDep
from app.backend.schemas import UserCreate, UserPublic

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/users", tags=["users"])


@router.post("", response_model=UserPublic, status_code=status.HTTP_201_CREATED)
def create_user(
    user_in: UserCreate, session: SessionDep, settings: SettingsDep, _admin: AdminUser
) -> UserPublic:
    """Create a user with a role (admin only); 409 when the name is taken."""
    user = crud.create_user(
        session=session,
        username=user_in.username,
        password=user_in.password,
        role=user_in.role,
        scrypt_n=settings.scrypt_n,
    )
    return UserPublic.model_validate(user)


@router.get("", response_model=list[UserPublic])
def list_users(session: SessionDep, _admin: AdminUser) -> list[UserPublic]:
    """All users (admin only)."""
    return [UserPublic.model_validate(user) for user in crud.list_users(session=session)]
