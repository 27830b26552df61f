from app.services.importing import import_path
from tests.app.factories import image_folder


def test_empty_index_explains_how_to_start(admin_client):
    page = admin_client.get("/")
    assert page.status_code == 200
    assert b"flask --app app egonet demo" in page.data


def test_index_grid_viewer_and_media(app, admin_client, tmp_path):
    client = admin_client
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=3, depth=True), activity="cooking")
    page = client.get("/")
    assert b"cooking" in page.data and b"3 frames" in page.data
    api = client.get("/api/activities").get_json()
    (activity,) = api["activities"]
    assert activity["by_status"]["todo"] == 3

    grid = client.get(f"/activities/{activity['id']}")
    assert grid.status_code == 200 and grid.data.count(b'class="frame-tile"') == 3

    frames = client.get(f"/api/activities/{activity['id']}/frames").get_json()["frames"]
    first = frames[0]
    viewer = client.get(f"/frames/{first['id']}")
    assert viewer.status_code == 200 and b"Depth" in viewer.data and b'id="next"' in viewer.data
    assert f'href="/label/frames/{first["id"]}"'.encode() in viewer.data
    for url, mimetype in ((first["rgb_url"], "image/png"), (first["depth_url"], "image/png"), (f"/frames/{first['id']}/thumb.jpg", "image/jpeg")):
        with client.get(url) as response:
            assert response.status_code == 200 and len(response.data) > 100, url
            assert response.mimetype == mimetype


def test_errors_are_json_for_the_api_and_pages_for_browsers(admin_client):
    client = admin_client
    response = client.get("/api/frames/999")
    assert response.status_code == 404
    body = response.get_json()
    assert body["error"] == "not_found" and body["message"] and body["fields"] == {}
    page = client.get("/frames/999")
    assert page.status_code == 404 and page.mimetype == "text/html" and b"Back to the activities" in page.data
    assert client.get("/activities/1?page=0").status_code in (400, 404)
    with client.get("/media/../../etc/passwd") as response:
        assert response.status_code == 404
