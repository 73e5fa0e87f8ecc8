//! Who may open a session, and who may write: anonymous sessions read only, users log in
//! with a name and password (only on secure endpoints) and write when allowed to.

use ::opcua::crypto::SecurityPolicy;
use ::opcua::server::address_space::AccessLevel;
use ::opcua::server::authenticator::{
    AuthManager, Password, UserToken, user_pass_security_policy_id,
};
use ::opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerEndpoint};
use ::opcua::types::{Error, NodeId, StatusCode, UAString, UserTokenPolicy, UserTokenType};

/// The policy id of anonymous tokens (the one async-opcua checks).
const ANONYMOUS_POLICY: &str = "anonymous";

/// A user with the password read at start.
#[derive(Clone, PartialEq, Eq)]
pub struct User {
    /// The user name.
    pub name: String,
    /// The password.
    pub password: String,
    /// Whether the user may write (with `--allow-writes`).
    pub write: bool,
}

impl std::fmt::Debug for User {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("User")
            .field("name", &self.name)
            .field("write", &self.write)
            .finish_non_exhaustive()
    }
}

/// The server's users and whether anonymous sessions are allowed.
#[derive(Debug, Clone)]
pub struct Users {
    users: Vec<User>,
    anonymous: bool,
    writes: bool,
}

impl Users {
    /// `users`; anonymous sessions when `anonymous`; writes at all when `writes`
    /// (`--allow-writes`).
    pub fn new(users: Vec<User>, anonymous: bool, writes: bool) -> Self {
        Self {
            users,
            anonymous,
            writes,
        }
    }

    /// Whether the session's user may write.
    pub fn may_write(&self, token: &UserToken) -> bool {
        self.writes
            && !token.is_anonymous()
            && self.users.iter().any(|u| u.name == token.0 && u.write)
    }

    /// Whether anonymous sessions are allowed.
    pub fn anonymous(&self) -> bool {
        self.anonymous
    }
}

#[async_trait::async_trait]
impl AuthManager for Users {
    async fn authenticate_anonymous_token(&self, endpoint: &ServerEndpoint) -> Result<(), Error> {
        if self.anonymous && endpoint.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID) {
            Ok(())
        } else {
            Err(Error::new(
                StatusCode::BadIdentityTokenRejected,
                "anonymous sessions are off on this endpoint",
            ))
        }
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let secure = endpoint.security_policy() != SecurityPolicy::None;
        let found = self
            .users
            .iter()
            .find(|u| u.name == username && same_secret(&u.password, password.get()));
        match found {
            Some(user) if secure => Ok(UserToken(user.name.clone())),
            _ => {
                tracing::warn!("OPC UA login refused for user {username:?}");
                Err(Error::new(
                    StatusCode::BadUserAccessDenied,
                    format!("user {username:?}: wrong name or password"),
                ))
            }
        }
    }

    fn effective_user_access_level(
        &self,
        token: &UserToken,
        user_access_level: AccessLevel,
        _node_id: &NodeId,
    ) -> AccessLevel {
        if self.may_write(token) {
            user_access_level
        } else {
            user_access_level - AccessLevel::CURRENT_WRITE
        }
    }

    /// The cell's methods (`Objects/Gateway/Alarms`: acknowledge, shelve, unshelve) are
    /// for those who may write, as writes are; namespace 0's (the server's own) for all.
    fn is_user_executable(&self, token: &UserToken, method_id: &NodeId) -> bool {
        method_id.namespace == 0 || self.may_write(token)
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = Vec::new();
        if self.anonymous && endpoint.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID) {
            policies.push(UserTokenPolicy {
                policy_id: UAString::from(ANONYMOUS_POLICY),
                token_type: UserTokenType::Anonymous,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        // Passwords only where the channel is encrypted or signed with the server's key.
        if !self.users.is_empty() && endpoint.security_policy() != SecurityPolicy::None {
            policies.push(UserTokenPolicy {
                policy_id: user_pass_security_policy_id(endpoint),
                token_type: UserTokenType::UserName,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        policies
    }
}

/// Compares two secrets in time that does not depend on where they differ.
fn same_secret(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    a.len() == b.len() && a.iter().zip(b).fold(0_u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn users(writes: bool) -> Users {
        Users::new(
            vec![
                User {
                    name: "op".into(),
                    password: "pw".into(),
                    write: true,
                },
                User {
                    name: "viewer".into(),
                    password: "pw2".into(),
                    write: false,
                },
            ],
            true,
            writes,
        )
    }

    #[test]
    fn only_a_writing_user_writes_and_only_with_writes_allowed() {
        let on = users(true);
        assert!(on.may_write(&UserToken("op".into())));
        assert!(!on.may_write(&UserToken("viewer".into())));
        assert!(!on.may_write(&UserToken(ANONYMOUS_USER_TOKEN_ID.into())));
        assert!(!users(false).may_write(&UserToken("op".into())));
    }

    #[test]
    fn only_a_writing_user_may_call_the_cells_methods_and_everyone_the_servers_own() {
        let acknowledge = NodeId::new(2, "gateway/Alarms/Acknowledge");
        let resend = NodeId::new(0, 12873_u32);
        let on = users(true);
        let anonymous = UserToken(ANONYMOUS_USER_TOKEN_ID.into());
        assert!(on.is_user_executable(&UserToken("op".into()), &acknowledge));
        assert!(!on.is_user_executable(&UserToken("viewer".into()), &acknowledge));
        assert!(!on.is_user_executable(&anonymous, &acknowledge));
        assert!(!users(false).is_user_executable(&UserToken("op".into()), &acknowledge));
        assert!(on.is_user_executable(&anonymous, &resend));
    }

    #[test]
    fn a_user_who_may_not_write_sees_no_current_write_access() {
        let level = AccessLevel::CURRENT_READ | AccessLevel::CURRENT_WRITE;
        let node = NodeId::new(2, "jbc1.air_temperature");
        let on = users(true);
        assert_eq!(
            on.effective_user_access_level(&UserToken("viewer".into()), level, &node)
                .bits(),
            AccessLevel::CURRENT_READ.bits()
        );
        assert_eq!(
            on.effective_user_access_level(&UserToken("op".into()), level, &node)
                .bits(),
            level.bits()
        );
    }

    #[test]
    fn secrets_compare_equal_only_when_equal() {
        assert!(same_secret("abc", "abc"));
        assert!(!same_secret("abc", "abd"));
        assert!(!same_secret("abc", "abcd"));
    }
}
