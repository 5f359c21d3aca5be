"""Database operations used by the routes; every function takes keyword-only arguments and commits its work."""

from app.backend.crud.changes import element_changes
from app.backend.crud.elements import (
    create_elements,
    delete_element,
    get_element,
    public,
    query_elements,
    update_element,
)
from app.backend.crud.review import element_history, restore_version, review_element
from app.backend.crud.sites import create_site, get_site, list_sites, site_counts, site_extent, site_layers
from app.backend.crud.users import (
    authenticate,
    create_user,
    ensure_admin,
    issue_token,
    list_users,
    user_for_token,
)

__all__ = [
    "authenticate",
    "create_elements",
    "create_site",
    "create_user",
    "delete_element",
    "element_changes",
    "element_history",
    "ensure_admin",
    "get_element",
    "get_site",
    "issue_token",
    "list_sites",
    "list_users",
    "public",
    "query_elements",
    "restore_version",
    "review_element",
    "site_counts",
    "site_extent",
    "site_layers",
    "update_element",
    "user_for_token",
]
