//! The monitor on a real (loopback) bus: a stand-in run publishes on its topics and holds a
//! liveliness token; the record must hold what it published, and `plot` must draw it.

use std::time::Duration;

use node::{BusConfig, NodeArgs, ZenohMode};
use proto::{NodeId, Role, topics};

use super::fixtures;
use super::{MonitorArgs, watch};
use serde_json::Value;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn records_what_a_run_publishes_and_plot_draws_it() {
    let endpoint = format!("tcp/127.0.0.1:{}", node::free_loopback_port().expect("a free port"));
    let run = fixtures::run();
    let config = BusConfig { listen: vec![endpoint.clone()], ..BusConfig::default() };
    let session = zenoh::open(config.to_zenoh().unwrap()).await.unwrap();
    let executor = NodeId { role: Role::Executor, id: 0 };
    let token = session.liveliness().declare_token(topics::liveliness(&run, executor)).await.unwrap();

    let dir = std::env::temp_dir().join(format!("sac-lsp-monitor-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.join("run/monitor.jsonl");
    let args = MonitorArgs {
        node: NodeArgs {
            config: None,
            run_id: fixtures::RUN.into(),
            id: 0,
            connect: vec![endpoint],
            listen: Vec::new(),
            mode: ZenohMode::Peer,
            multicast: false,
            zenoh_config: None,
            zenoh_cfg: Vec::new(),
        },
        out: Some(out.clone()),
        tensorboard: None,
        no_tensorboard: false,
        interval_ms: 100,
        duration_s: None,
        quiet: true,
    };
    let publish = async {
        for i in 0..40u64 {
            let put = |key: String, bytes: Vec<u8>| {
                let session = session.clone();
                async move { session.put(key, bytes).await.unwrap() }
            };
            put(topics::stats(&run, NodeId { role: Role::Learner, id: 0 }), fixtures::learner()).await;
            put(topics::stats(&run, executor), fixtures::executor(0, (i * 100) as f64, 100.0, false)).await;
            put(topics::control_step(&run), fixtures::step(5000)).await;
            put(topics::episodes(&run, 0), fixtures::episode(0, i, i as f64, (i + 1) * 100)).await;
            if i % 5 == 4 {
                put(topics::evaluation(&run), fixtures::eval(i / 5, 100.0 * i as f64)).await;
            }
            put(topics::stats_all(&run).replace("**", "learner/0"), b"not a frame".to_vec()).await;
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    };
    let (watched, ()) = tokio::join!(watch(&args, Some(Duration::from_secs(3))), publish);
    watched.unwrap();
    drop(token);
    session.close().await.unwrap();

    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<Value> = text.lines().map(|l| serde_json::from_str::<Value>(l).unwrap()).collect();
    let of_type = |t: &str| lines.iter().filter(|l| l.get("type").and_then(Value::as_str) == Some(t)).count();
    assert_eq!(lines[0].get("type").and_then(Value::as_str), Some("start"));
    assert_eq!(lines[0].get("run_id").and_then(Value::as_str), Some(fixtures::RUN));
    assert!(of_type("tick") >= 10, "{text}");
    // Some early messages may precede the connection; most must arrive.
    assert!(of_type("episode") >= 20, "{text}");
    assert!(of_type("eval") >= 4, "{text}");
    let last = lines.last().unwrap();
    assert_eq!(last.get("type").and_then(Value::as_str), Some("tick"));
    assert_eq!(last.get("learner_step").and_then(Value::as_u64), Some(5000));
    assert_eq!(last.get("updates_per_s").and_then(Value::as_f64), Some(612.5));
    let executors = last.get("executors").and_then(Value::as_array).unwrap();
    assert_eq!(executors.len(), 1);
    assert_eq!(executors[0].get("alive").and_then(Value::as_bool), Some(true));
    assert_eq!(executors[0].get("env_steps").and_then(Value::as_u64), Some(4000));
    assert_eq!(last.get("env_steps_total").and_then(Value::as_u64), Some(4000));
    let garbage = last.get("undecodable").and_then(|u| u.get("stats")).and_then(Value::as_u64);
    assert!(garbage.is_some_and(|n| n >= 20), "{garbage:?}");
    assert_eq!(last.get("undecodable").and_then(|u| u.get("episodes")).and_then(Value::as_u64), Some(0));

    // TensorBoard beside the record holds the same episodes and evaluations.
    let boards: Vec<_> =
        std::fs::read_dir(dir.join("run/tensorboard")).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(boards.len(), 1, "{boards:?}");
    let events = crate::tensorboard::read::events(&boards[0]);
    let tagged = |tag: &str| events.iter().filter(|e| e.scalars.iter().any(|(t, _)| t == tag)).count();
    assert_eq!(tagged("train/episode_return"), of_type("episode"));
    assert_eq!(tagged("eval/fixed_latent/return_mean"), of_type("eval"));
    assert!(tagged("learner/q_loss") >= 1);

    crate::plot::run(&crate::plot::PlotArgs { input: out.clone(), out_dir: None }).unwrap();
    for name in ["return_vs_env_steps.png", "return_vs_wall_clock.png", "updates_per_s.png"] {
        let png = std::fs::read(dir.join("run").join(name)).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
