use super::*;

#[test]
fn rejected_certificates_are_cut_back_to_the_newest() {
    let dir = tempfile::tempdir().unwrap();
    let start = std::time::SystemTime::now() - Duration::from_secs(1000);
    for n in 0..10_u64 {
        let path = dir.path().join(format!("cert{n}.der"));
        std::fs::write(&path, b"x").unwrap();
        let file = std::fs::File::options().write(true).open(&path).unwrap();
        file.set_modified(start + Duration::from_secs(n)).unwrap();
    }
    assert_eq!(trim_rejected(dir.path(), 4).unwrap(), 6);
    let mut left: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["cert6.der", "cert7.der", "cert8.der", "cert9.der"]);
    assert_eq!(trim_rejected(dir.path(), 4).unwrap(), 0);
}

#[cfg(unix)]
#[test]
fn the_private_key_is_readable_by_this_user_only_even_when_an_older_start_left_it_open() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let pki = dir.path().join("pki");
    let config = OpcuaConfig::at("127.0.0.1", 4840);
    ensure_certificate(&pki, &config).unwrap();
    let private = pki.join("private");
    let mode = |path: &Path| std::fs::metadata(path).unwrap().permissions().mode() & 0o777;
    let key = private.join("private.pem");
    assert_eq!(mode(&private), 0o700);
    assert_eq!(mode(&key), 0o600);
    // As an earlier version left it: the next start closes it again.
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    std::fs::set_permissions(&private, std::fs::Permissions::from_mode(0o755)).unwrap();
    ensure_certificate(&pki, &config).unwrap();
    assert_eq!(mode(&private), 0o700);
    assert_eq!(mode(&key), 0o600);
}
