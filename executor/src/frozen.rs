//! A hierarchy's frozen levels, fetched once from the param server (`params/frozen`) before the
//! first step: the levels come with their content hash, which is recomputed here from what
//! arrived, and every weights frame must later carry the same hash.

use std::time::{Duration, Instant};

use agent::PolicyStack;
use node::{Bus, Shutdown};
use proto::{ContentHash, FrozenLevels};

use crate::lock;
use crate::weights::{FetchError, RETRY, query};

/// The stack and its hash.
#[derive(Debug)]
pub(crate) struct Fetched {
    pub stack: PolicyStack,
    pub hash: ContentHash,
}

/// Fetches `depth` frozen levels, retrying (and saying why every `deadline`) until they arrive and
/// check out; `None` if shutdown comes first. Bad replies are counted as `frozen/<reason>`.
pub(crate) async fn fetch(
    bus: &Bus,
    depth: usize,
    timeout: Duration,
    deadline: Duration,
    rejects: &std::sync::Mutex<node::Rejects>,
    mut shutdown: Shutdown,
) -> Option<Fetched> {
    let started = Instant::now();
    let mut said = Instant::now();
    loop {
        match query::<FrozenLevels>(bus, proto::Topic::ParamsFrozen, timeout).await {
            Ok(Some(message)) => match check(message, depth) {
                Ok(fetched) => {
                    tracing::info!(levels = depth, content_hash = %fetched.hash, "frozen levels received");
                    return Some(fetched);
                }
                Err((reason, detail)) => {
                    lock(rejects).record(&format!("frozen/{reason}"), &detail, Instant::now())
                }
            },
            Err(FetchError::Decode(error)) => lock(rejects).decode_failed("frozen", &error),
            unavailable => {
                let why = match unavailable {
                    Err(FetchError::Unavailable(why)) => why,
                    _ => "no param server answered".to_string(),
                };
                if said.elapsed() >= deadline {
                    said = Instant::now();
                    let waited_s = started.elapsed().as_secs();
                    tracing::warn!(%why, waited_s, "waiting for the param server's frozen levels");
                }
            }
        }
        tokio::select! {
            _ = shutdown.wait() => return None,
            _ = tokio::time::sleep(RETRY) => {}
        }
    }
}

/// Builds the stack from a reply and checks it is what the run expects and what the reply claims.
fn check(message: FrozenLevels, depth: usize) -> Result<Fetched, (&'static str, String)> {
    if message.levels.len() != depth {
        let detail = format!("{} levels, [hierarchy] names {depth}", message.levels.len());
        return Err(("depth", detail));
    }
    let weights: Vec<&[u8]> = message.levels.iter().map(|l| l.safetensors.as_slice()).collect();
    let stack = PolicyStack::from_weights(&weights).map_err(|e| ("bad_level", e.to_string()))?;
    let hash = stack.content_hash().map(ContentHash).map_err(|e| ("bad_level", e.to_string()))?;
    if hash != message.content_hash {
        let detail = format!("the levels hash to {hash}, the reply claims {}", message.content_hash);
        return Err(("hash_mismatch", detail));
    }
    Ok(Fetched { stack, hash })
}

#[cfg(test)]
mod tests {
    use agent::{AgentConfig, Learner};
    use proto::FrozenLevel;

    use super::*;

    fn level(seed: u64) -> FrozenLevel {
        let cfg = AgentConfig {
            critic_hidden: vec![4],
            embedding_layers: vec![4, 2],
            ..AgentConfig::for_task(3, 2)
        };
        FrozenLevel { safetensors: Learner::new(cfg, seed).unwrap().snapshot().unwrap().safetensors }
    }

    #[test]
    fn a_checkpoint_embeds_no_more_levels_than_the_wire_carries() {
        assert_eq!(agent::MAX_FROZEN_LEVELS, proto::MAX_FROZEN_LEVELS);
    }

    #[test]
    fn a_reply_must_hash_to_what_it_claims_and_have_the_run_s_depth() {
        let levels = vec![level(1)];
        let hash = PolicyStack::from_weights(&[&levels[0].safetensors]).unwrap().content_hash().unwrap();
        let reply = |content_hash, levels| FrozenLevels { content_hash: ContentHash(content_hash), levels };
        let fetched = check(reply(hash, levels.clone()), 1).unwrap();
        assert_eq!((fetched.hash, fetched.stack.depth()), (ContentHash(hash), 1));
        assert_eq!(check(reply(hash, levels.clone()), 2).unwrap_err().0, "depth");
        assert_eq!(check(reply([0; 32], levels), 1).unwrap_err().0, "hash_mismatch");
        assert_eq!(check(reply(hash, vec![level(2)]), 1).unwrap_err().0, "hash_mismatch");
        let garbage = vec![FrozenLevel { safetensors: vec![9; 16] }];
        assert_eq!(check(reply(hash, garbage), 1).unwrap_err().0, "bad_level");
    }
}
